"""Automatic checks of the course's exercises (``exercises/NN_topic.ipynb``).

One module per chapter (:mod:`racing_lib.grading.ch01`, ...), each with one ``check_*`` function
per exercise; :mod:`racing_lib.grading.grader` is the small framework they share. A check takes
the reader's function, compares its answers with :mod:`racing_lib` on a few cases and returns a
:class:`~racing_lib.grading.grader.CheckResult` that says, in physical terms, what is right or
wrong; a function that is still the template's is reported as "not done yet".
"""

from racing_lib.grading.grader import (
    CheckResult,
    score,
)

__all__ = ["CheckResult", "score"]
