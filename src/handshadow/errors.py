"""The one base class of every error whose message is all a user needs (bad input, missing
files, unusable output folder). The command line prints it on one line and exits with 2."""


class HandshadowError(ValueError):
    """An expected failure with a user-facing, one-line message."""
