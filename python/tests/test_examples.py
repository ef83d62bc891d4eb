"""The Python examples run (smoke test: exit code 0 and their key output)."""

import os
import subprocess
import sys

import pytest

EXAMPLES = os.path.join(os.environ.get("MOREAU_EXAMPLES", "examples"), "python")


@pytest.mark.parametrize("script,expected", [
    ("s3_sweeping.py", "enter"),
    ("f1_order_study.py", "observed order"),
    ("h1_thermostat.py", "relay thermostat"),
    ("s3_contact_sweep.py", "max |contact time - closed form|"),
    ("thermostat_period.py", "runs without a periodic regime"),
    ("shooting_stewart_anitescu.py", "closed form -1.427572232083"),
])
def test_example_runs(script, expected, tmp_path):
    arguments = [sys.executable, os.path.join(EXAMPLES, script)]
    if script in ("s3_sweeping.py", "h1_thermostat.py", "thermostat_period.py"):
        arguments.append(str(tmp_path / "plot.png"))
    env = dict(os.environ, MPLBACKEND="Agg")
    completed = subprocess.run(arguments, capture_output=True, text=True, env=env, check=False,
                               timeout=300)
    assert completed.returncode == 0, completed.stderr
    assert expected in completed.stdout
    if len(arguments) == 3:
        assert (tmp_path / "plot.png").stat().st_size > 0


# The demonstrations of docs/sensitivities.md in shortened form (their full versions are
# documented there with measured iterations and times). They exit non-zero unless they
# converge to the known answer.
@pytest.mark.parametrize("script,arguments,expected", [
    ("wave_rider_shooting.py", ["--intervals", "10"], "`moreau ocp wave_rider`: 0.336357343835"),
    ("crowd_estimation.py", ["--agents", "100", "--tf", "1"], "estimate s = "),
])
def test_demonstration_converges(script, arguments, expected):
    completed = subprocess.run([sys.executable, os.path.join(EXAMPLES, script), *arguments],
                               capture_output=True, text=True, check=False, timeout=600)
    assert completed.returncode == 0, completed.stdout + completed.stderr
    assert expected in completed.stdout
