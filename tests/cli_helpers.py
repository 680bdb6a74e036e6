"""Shared by the end-to-end run-directory tests: the hostile-controller plugin, the CLI in a
subprocess and small matrix files (not a test module)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

PLUGIN = '''
import ctypes, os, signal
from controllers.base import Controller, register
from plant.drive import DriveCommand

LEVEL = 0.0


class _Hostile(Controller):
    description = "test only: misbehaves at its 21st sample"

    def reset(self, params, rng):
        self.n = 0

    def step(self, y):
        self.n += 1
        if self.n > 20:
            self.misbehave()
        return DriveCommand.hold(LEVEL)

    def misbehave(self):
        pass


@register("t-hold")
class Hold(_Hostile):
    pass


@register("t-exit")
class Exit(_Hostile):
    def misbehave(self):
        os._exit(3)


@register("t-kill")
class Kill(_Hostile):
    def misbehave(self):
        os.kill(os.getpid(), signal.SIGKILL)


@register("t-hang")
class Hang(_Hostile):
    def misbehave(self):          # once: sleep in C, where no Python-level check can run
        if not getattr(self, "slept", False):
            self.slept = True
            ctypes.CDLL(None).sleep(int(os.environ.get("T_HANG_S", "30")))


@register("t-sysexit")
class SysExit(_Hostile):
    def misbehave(self):
        raise SystemExit(4)


@register("t-kbint")
class KbInt(_Hostile):
    def misbehave(self):
        raise KeyboardInterrupt
'''

def cli(*args, cwd=ROOT, timeout: float = 240, env=None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "reports.cli", *map(str, args)], cwd=cwd, capture_output=True,
                          text=True, timeout=timeout, env=env)


def write_matrix(directory: Path, controllers, seeds=(0,), duration=1, time_limit=None, name="m.toml",
                 extra="") -> Path:
    (directory / "hostile_plugin.py").write_text(PLUGIN)
    text = (f'[matrix]\nplugins = ["hostile_plugin"]\ncontrollers = {json.dumps(list(controllers))}\n'
            f'scenarios = ["thesis"]\nseeds = {list(seeds)}\nduration_s = {duration}\nwarmup_s = 0.2\n')
    if time_limit is not None:
        text += f"time_limit_s = {time_limit}\n"
    path = directory / name
    path.write_text(text + extra)
    return path
