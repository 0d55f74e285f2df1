"""Every command that reads a recording answers a file that is not MCAP with one line naming it,
not a traceback, and leaves the file as it was."""
from __future__ import annotations

import pytest

from omninav.cli.main import main as cli_main


@pytest.mark.parametrize("command", [
    ["replay", "{f}", "--into", "chassis", "--compare"],
    ["replay", "{f}"],
    ["report", "{f}", "-o", "{d}/x.png"],
    ["recover", "{f}"],
])
def test_a_six_byte_file_is_not_an_mcap_file(tmp_path, capsys, caplog, command):
    bad = tmp_path / "six.mcap"
    bad.write_bytes(b"abcdef")
    code = cli_main([part.format(f=bad, d=tmp_path) for part in command])
    err = capsys.readouterr().err + caplog.text         # live replay logs its errors
    assert code != 0 and "Traceback" not in err
    lines = [line for line in err.splitlines() if "not an MCAP file" in line]
    assert len(lines) == 1 and str(bad) in lines[0]
    assert bad.read_bytes() == b"abcdef"
