class GMRInputError(ValueError):
    """A user mistake in the data or options given to gmr_jax.

    The message names the problem and how to fix it. The command line prints it as one line
    and exits with status 2.
    """
