"""Generic optimizers the experiments build on; nothing here knows of cars or tracks."""
