"""Node processes for the bench tests: started from the venv's console scripts, killed at the end."""
import json
import subprocess
import sys
from pathlib import Path

import pytest

from domains import tied

VENV_BIN = Path(sys.executable).parent


@pytest.fixture
def procs():
    """A list the test appends its processes to (``start``); any still running are killed."""
    started = []
    yield started
    for p in started:
        if p.poll() is None:
            p.kill()
        p.wait(timeout=10)


def start(procs, args, env, **kw):
    """Console script ``args[0]`` with arguments, output piped (text), registered in ``procs``."""
    p = subprocess.Popen(tied([str(VENV_BIN / args[0]), *args[1:]]), env=env, stdout=subprocess.PIPE,
                         stderr=subprocess.STDOUT, text=True, **kw)
    procs.append(p)
    return p


def summary(output: str) -> dict:
    """bench_node's last ``summary: {...}`` line."""
    line = [x for x in output.splitlines() if x.startswith("summary: ")][-1]
    return json.loads(line[len("summary: "):])
