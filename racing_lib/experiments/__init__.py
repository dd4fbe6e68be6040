"""Experiments: closed-loop laps, identification, tuning, the pipeline and the paper's tables.

The layer above control: it drives plants with controllers along plans. Nothing below imports it.
"""
