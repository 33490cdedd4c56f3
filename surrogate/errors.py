"""The errors of the data and training stages, apart from the modules that raise them so that a command
can name them without loading numpy's statistics or torch (a refused command answers at once)."""


class DatasetError(ValueError):
    """A dataset directory that cannot be used as asked."""


class TrainError(ValueError):
    """A run that cannot be started or resumed as asked."""
