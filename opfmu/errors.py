"""The one error type of the command line: a mistake in what the user asked for, reported by
`opfmu.cli.main` as one line on stderr with exit code 2. Every command module raises it; none
imports another command module for it."""


class UserError(Exception):
    """A mistake in what the user asked for: reported as one line, exit code 2."""
