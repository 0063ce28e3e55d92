"""liblsl's settings: the user's ``lsl_api.cfg`` found as liblsl finds it; without one,
liblsl's start-up INFO lines kept off the terminal."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from mocapkit.io.lsl import user_config_files


def test_user_config_files_in_liblsl_order(tmp_path, monkeypatch):
    home = tmp_path / "home"
    (home / "lsl_api").mkdir(parents=True)
    work = tmp_path / "work"
    work.mkdir()
    named = tmp_path / "named.cfg"
    monkeypatch.setenv("HOME", str(home))
    monkeypatch.chdir(work)
    monkeypatch.delenv("LSLAPICFG", raising=False)
    etc = Path("/etc/lsl_api/lsl_api.cfg")
    system = [etc] if etc.is_file() else []
    assert user_config_files() == system

    (home / "lsl_api" / "lsl_api.cfg").write_text("[log]\nlevel = 0\n")
    (work / "lsl_api.cfg").write_text("[log]\nlevel = 0\n")
    named.write_text("[log]\nlevel = 0\n")
    monkeypatch.setenv("LSLAPICFG", str(named))
    found = user_config_files()
    assert found[:3] == [named, Path("lsl_api.cfg"), home / "lsl_api" / "lsl_api.cfg"]

    monkeypatch.setenv("LSLAPICFG", str(tmp_path / "missing.cfg"))
    assert Path("lsl_api.cfg") == user_config_files()[0]


@pytest.mark.skipif(
    Path("/etc/lsl_api/lsl_api.cfg").is_file(), reason="this machine has a system lsl_api.cfg"
)
def test_liblsl_quiet_without_a_user_config(tmp_path):
    pytest.importorskip("pylsl")
    script = (
        "from mocapkit.io.lsl import pylsl\n"
        "lsl = pylsl()\n"
        "info = lsl.StreamInfo('quiet-test', 'Mocap', 3, 60.0, 'float32', 'q')\n"
        "outlet = lsl.StreamOutlet(info)\n"
        "print('made', outlet is not None)\n"
    )
    env = {k: v for k, v in os.environ.items() if k != "LSLAPICFG"}
    env["HOME"] = str(tmp_path)
    done = subprocess.run(
        [sys.executable, "-c", script],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
        timeout=60,
        check=True,
    )
    assert "made True" in done.stdout
    assert "INFO|" not in done.stderr, done.stderr
