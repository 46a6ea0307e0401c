"""cpapfit: a personalised CPAP mask cushion from a facial depth scan."""

__version__ = "0.1.0"
