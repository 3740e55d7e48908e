"""The CLI's last line of defence (issue 15): an OS error (a full disk) or a bug ends in one
line on stderr and a documented exit status, never a traceback."""

from __future__ import annotations

import errno

import pytest

from controller import cli


@pytest.mark.parametrize(("error", "status", "text"), [
    (OSError(errno.ENOSPC, "No space left on device", "/var/lib/finepos/datasets/nn1.npz"), 1,
     "finepos: error: No space left on device (/var/lib/finepos/datasets/nn1.npz)"),
    (OverflowError("int too large to convert to float"), 1,
     "finepos: internal error: OverflowError: int too large to convert to float"),
])
def test_errors_end_in_one_line(monkeypatch, capsys, error, status, text):
    def failing(args):
        raise error

    args = cli.build_parser().parse_args(["ctl", "status"])
    args.func = failing  # a subcommand that fails the way a full disk or a bug does
    monkeypatch.setattr(cli, "build_parser", lambda command=None: _Parser(args))
    assert cli.main(["ctl", "status"]) == status
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].startswith(text) and "Traceback" not in "\n".join(err)


class _Parser:
    def __init__(self, args) -> None:
        self._args = args

    def parse_args(self, argv):
        return self._args


SCRIPT = r"""
import sys
from pathlib import Path
from controller import cli
from drivers.core.files import atomic_write_bytes

target = Path(sys.argv[1])

def writing_forever(args):
    print("writing", flush=True)
    while True:  # a long train/acquire writing its result again and again
        atomic_write_bytes(target, b"new" * 30_000)

args = cli.build_parser().parse_args(["ctl", "status"])
args.func = writing_forever
cli.build_parser = lambda command=None: type("P", (), {"parse_args": lambda self, argv: args})()
sys.exit(cli.main([]))
"""


@pytest.mark.slow
def test_sigterm_mid_write_exits_143_with_one_line_and_no_temp_file(tmp_path):
    import signal
    import subprocess
    import sys
    from pathlib import Path

    target = tmp_path / "model.fpm"
    target.write_bytes(b"old")
    repo = Path(__file__).resolve().parents[2]
    process = subprocess.Popen([sys.executable, "-c", SCRIPT, str(target)], cwd=repo,
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    assert process.stdout.readline().strip() == "writing"
    process.send_signal(signal.SIGTERM)
    _, err = process.communicate(timeout=30)
    assert process.returncode == 143, err
    assert "Traceback" not in err and err.strip().startswith("finepos: terminated")
    assert target.read_bytes() in (b"old", b"new" * 30_000)
    assert not list(tmp_path.glob(".*.tmp"))
