"""Checkers for the exercise notebooks, one module per chapter (``ch01``, ``ch02``, ...).

Every checker answers with a ``Feedback``: ``not attempted`` for an untouched stub,
``correct``, or ``hint`` with a sentence naming what is wrong without giving the answer.
A checker never raises on a reader's code: an exception inside it becomes a hint.
Reference solutions live in ``ibc_tutorial.exercises.solutions`` (the tests import them).
"""

from ibc_tutorial.exercises.core import CORRECT, HINT, NOT_ATTEMPTED, Feedback, run_check

__all__ = ["Feedback", "run_check", "CORRECT", "HINT", "NOT_ATTEMPTED"]
