"""The core's exceptions: one hierarchy, so a caller can catch what the core refuses.

Every one is a ``ValueError`` (the argument was wrong, not the program) whose
message names the argument and says what was expected. A step that raises has
changed nothing: the caller's belief or estimate is as it was.
"""


class EstimationError(ValueError):
    """An input that a model or filter step refuses."""


class InvalidInputError(EstimationError):
    """An argument of the wrong type or shape, or with a value outside its domain (NaN,
    inf, a negative variance or probability, a range that is no reading)."""


class InputSizeError(InvalidInputError):
    """An input or measurement with another number of values than the model takes."""


class ZeroEvidenceError(EstimationError):
    """An observation that every state of the belief rules out: p(z) = 0."""


class NonFiniteResultError(EstimationError):
    """A step whose result would not be finite (an extreme input)."""


class MapError(EstimationError):
    """A map that cannot be used; the message names the field and says why."""
