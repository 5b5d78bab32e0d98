"""Every command the README, `docs/*.md`, `hardware/README.md` and `vlr demo`'s "next:" list
show runs as written, on its own default path, and exits 0.

Each runs in one scratch folder (a copy of `docs/`, the hardware examples, and the files a
command names as the user's own: `my_hand.yaml` is the simulated-hardware example, so the
hardware commands run against the emulated motors and the MuJoCo hand), in document order,
with one change to its environment: `VLR_SMOKE=1` (`vlr/smoke.py`), which caps particle
counts, actions, seeds, trials and episodes. No flag is added. A Python block runs as a
script; one that opens with `# NAME.py: COMMAND` is saved as NAME.py and COMMAND is run.
"""

from __future__ import annotations

import os
import re
import shlex
import shutil
import signal
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = ("README.md", *sorted(f"docs/{p.name}" for p in (ROOT / "docs").glob("*.md")),
        "hardware/README.md", "models/README.md")
PROGRAMS = ("vlr", "python", "make", "for")
TIMEOUT_S = 600

# What cannot run here, with why; everything else must.
NOT_HERE = {
    "make setup": "CI's own first step (.ci/run)",
    "make test": "CI's own second step; this test is part of it",
    "vlr camera-calibrate --camera 0": "needs a camera device (/dev/video0)",
    "vlr camera-calibrate --images views/": "needs the views the camera command saves",
}
# Commands that serve until Ctrl-C: they must start (print `ready`), then stop on SIGINT.
SERVERS = {"vlr emulate": "put this in"}
# Commands that ask the user for numbers: what a user would type (the load cells' newtons,
# a line per pull, rising with the pull).
STDIN = {"vlr tension-calibrate": "".join(f"{n} {n} {n}\n" for n in range(4, 12))}
MY_SETTINGS = "filter:\n  particles: 6000\nloop:\n  max_iterations: 10\n"


@dataclass(frozen=True)
class Shown:
    where: str          # file:line
    kind: str           # "shell" or "python"
    text: str           # the command as shown (for bash), or the script
    file: str = ""      # "NAME.py\nSCRIPT": saved before the command runs

    @property
    def line(self) -> str:
        """The command on one line, as a reader would type it."""
        return " ".join(self.text.replace("\\\n", " ").split())


def _shell_commands(block: str, first_line: int, where: str) -> list[Shown]:
    """The commands of a shell block: continuation lines joined, comments and output lines
    (starting with `#`) dropped, a quoted string spanning lines kept whole; an `export`
    goes before every later command of its block."""
    out, pending, start, exports = [], "", 0, ""
    for i, line in enumerate(block.splitlines()):
        if not pending:
            if not line.strip() or line.lstrip().startswith("#"):
                continue
            start = i
        pending += line + "\n"
        if line.rstrip().endswith("\\"):
            continue
        try:
            words = shlex.split(pending, comments=True)
        except ValueError:          # an open quote: the command goes on
            continue
        if words and words[0] == "export":
            exports += pending
        elif words and words[0] in PROGRAMS:
            out.append(Shown(f"{where}:{first_line + start}", "shell",
                             exports + pending.strip()))
        pending = ""
    assert not pending, f"{where}: an unfinished command: {pending!r}"
    return out


def shown_commands() -> list[Shown]:
    """Every command and Python block of the docs, in order, then `vlr demo`'s hints."""
    from vlr.sim.demo import NEXT_COMMANDS

    found = []
    for doc in DOCS:
        text = (ROOT / doc).read_text()
        for m in re.finditer(r"^```(\w*)\n(.*?)^```", text, re.S | re.M):
            lang, body = m.group(1), m.group(2)
            line = text[:m.start()].count("\n") + 2
            if lang in ("bash", "sh", "shell", "console"):
                found += _shell_commands(body, line, doc)
            elif lang == "python":
                head = body.splitlines()[0]
                named = re.match(r"#\s*(\w+\.py):\s*(.+)$", head)
                if named:
                    found.append(Shown(f"{doc}:{line}", "shell", named.group(2).strip(),
                                       file=f"{named.group(1)}\n{body}"))
                else:
                    found.append(Shown(f"{doc}:{line}", "python", body))
    found += [Shown("vlr demo's next:", "shell", cmd) for cmd, _ in NEXT_COMMANDS]
    return found


def _reason_not_here(cmd: Shown) -> str | None:
    return next((why for start, why in NOT_HERE.items() if cmd.line.startswith(start)), None)


@pytest.fixture(scope="module")
def workspace(tmp_path_factory) -> Path:
    """A user's folder: the docs (sweep files, results), the hardware examples, and the
    files the commands name as the user's own."""
    ws = tmp_path_factory.mktemp("user")
    shutil.copytree(ROOT / "docs", ws / "docs")
    (ws / "hardware").mkdir()
    for example in (ROOT / "hardware").glob("example*.yaml"):
        shutil.copy(example, ws / "hardware" / example.name)
    shutil.copy(ROOT / "hardware" / "example_sim_config.yaml", ws / "my_hand.yaml")
    (ws / "my_settings.yaml").write_text(MY_SETTINGS)
    return ws


def _env() -> dict[str, str]:
    env = dict(os.environ, VLR_SMOKE="1", MUJOCO_GL="egl", PYTHONUNBUFFERED="1")
    env["PATH"] = f"{Path(sys.executable).parent}{os.pathsep}{env.get('PATH', '')}"
    return env


def _run_server(cmd: str, ready: str, cwd: Path) -> tuple[int, str]:
    # Ctrl-C as a user's terminal delivers it: a suite started in the background by a
    # non-interactive shell (`make test &`) inherits SIGINT ignored, and so would the server.
    proc = subprocess.Popen(["bash", "-c", f"exec {cmd}"], cwd=cwd, env=_env(),
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    seen, t0 = "", time.monotonic()
    try:
        while ready not in seen and time.monotonic() - t0 < 120:
            line = proc.stdout.readline()
            if not line and proc.poll() is not None:
                break
            seen += line
        assert ready in seen, f"{cmd}: never ready:\n{seen}"
        proc.send_signal(signal.SIGINT)
        rest, _ = proc.communicate(timeout=30)
        return proc.returncode, seen + rest
    finally:
        if proc.poll() is None:
            proc.kill()


COMMANDS = shown_commands()


@pytest.mark.parametrize("cmd", COMMANDS, ids=[f"{c.where} {c.line[:60]}" for c in COMMANDS])
def test_shown_command_runs_on_its_default_path(cmd: Shown, workspace: Path):
    why = _reason_not_here(cmd)
    if why:
        pytest.skip(why)
    if cmd.file:
        name, _, script = cmd.file.partition("\n")
        (workspace / name).write_text(script)
    server = next((ready for start, ready in SERVERS.items() if cmd.line.startswith(start)),
                  None)
    t0 = time.monotonic()
    if server:
        code, output = _run_server(cmd.text, server, workspace)
        assert code in (0, 130), f"{cmd.where}: {cmd.text}\nexit {code}\n{output[-3000:]}"
        return
    stdin = next((text for start, text in STDIN.items() if cmd.line.startswith(start)), "")
    argv = [sys.executable, "-c", cmd.text] if cmd.kind == "python" else \
        ["bash", "-c", cmd.text]
    done = subprocess.run(argv, cwd=workspace, env=_env(), input=stdin, capture_output=True,
                          text=True, timeout=TIMEOUT_S)
    took = time.monotonic() - t0
    output = done.stdout[-2000:] + done.stderr[-3000:]
    assert done.returncode == 0, f"{cmd.where}: {cmd.text}\nexit {done.returncode}\n{output}"
    assert "Traceback" not in done.stderr, f"{cmd.where}: {cmd.text}\n{output}"
    print(f"{took:6.1f} s  {cmd.where}  {cmd.line[:80]}")


def test_every_doc_command_is_found():
    """The parser sees the README's main job and the multi-line commands whole."""
    texts = [c.line for c in COMMANDS]
    assert "vlr identify --object apple --out runs/apple" in texts
    assert any(t.startswith("vlr camera-calibrate --camera 0") and "--out camera.yaml" in t
               for t in texts)
    assert any(t.startswith("python -c") and "ray.shutdown()" in t for t in texts)
    assert any(c.file.startswith("my_policy.py") for c in COMMANDS)
    # A loop runs whole, after the `export` of its block.
    assert any(t.startswith("export NUMBA_CACHE_DIR") and "for i in 1 2; do" in t
               for t in texts)
