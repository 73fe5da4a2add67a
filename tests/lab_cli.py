"""``mitsuba-lab ARGV`` in the test's own process, for tests that check exit codes and messages."""
import io
import sys

from mitsuba_lab import cli


def run(argv) -> tuple[int, str, str]:
    """(exit status, stdout, stderr) of ``mitsuba-lab ARGV``, argparse's usage errors included."""
    out, err = io.StringIO(), io.StringIO()
    old_out, old_err, sys.stdout, sys.stderr = sys.stdout, sys.stderr, out, err
    try:
        code = cli.main(argv)
    except SystemExit as exc:
        code = exc.code
    finally:
        sys.stdout, sys.stderr = old_out, old_err
    return code, out.getvalue(), err.getvalue()
