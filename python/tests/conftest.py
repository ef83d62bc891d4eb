"""Shared helpers: the command-line tool built beside the module (MOREAU_CLI, set by CTest)."""

import json
import os
import subprocess

import pytest


@pytest.fixture(scope="session")
def cli():
    path = os.environ.get("MOREAU_CLI")
    if not path or not os.path.exists(path):
        pytest.fail("MOREAU_CLI must name the built moreau executable (ctest sets it)")

    def run(arguments, out_dir):
        completed = subprocess.run([path, *arguments, "--out", str(out_dir), "--no-plot",
                                    "--quiet"], capture_output=True, text=True, check=False)
        assert completed.returncode == 0, completed.stderr
        with open(os.path.join(out_dir, "summary.json"), encoding="utf-8") as f:
            return json.load(f)

    return run
