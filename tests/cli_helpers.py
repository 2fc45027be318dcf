"""Running the ``dv2s`` CLI in-process from tests, and reading its one-line errors."""

from dv2s_gym.cli import main


def run(capsys, *argv):
    """``(exit code, stdout, stderr)`` of ``dv2s ARGV`` run in this process."""
    code = main([str(a) for a in argv])
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def one_line_error(err: str) -> str:
    """The single ``dv2s: error: ...`` line of ``err``; fails if there is more, or a traceback."""
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("dv2s: error: ") and "Traceback" not in err, err
    return lines[0]
