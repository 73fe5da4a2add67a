"""The ``mitsuba-lab`` commands, one module per verb.

Each module has ``add_arguments(parser)`` (its options and description) and
``run(args, out) -> int`` (the exit status; errors are raised and reported by
``cli.main`` in one line). ``cli.COMMANDS`` names them; a module is imported only
when its verb's subparser is built or its verb runs, so none may import Mitsuba,
Dr.Jit or numpy at module level. ``args`` holds the argument types they share.
"""
