"""The one exception type that the command line turns into a single line and exit status 2."""


class ArsimError(Exception):
    """Bad input or an unmet requirement, with a message that says what is wrong and how to fix it."""
