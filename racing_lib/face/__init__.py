"""What a person sees: the command line, the figures and the notebooks' set-up.

The top layer: it may import everything below and nothing imports it.
"""
