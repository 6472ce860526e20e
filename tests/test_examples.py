"""The cluster examples in examples/ stay runnable: their sr3d options exist and the indexed Job
passes its completion count to --shard auto."""

from __future__ import annotations

import re
from pathlib import Path

import yaml
from click.testing import CliRunner

from sr3d_cli.cli import cli
from sr3d_cli.cli.stage_loop import parse_shard

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def _sr3d_calls(text: str) -> list[tuple[str, list[str]]]:
    """(command, its --options) of every uncommented sr3d call, continuation lines joined."""
    lines = [ln for ln in text.replace("\\\n", " ").splitlines()
             if not ln.lstrip().startswith("#")]
    calls = []
    for ln in lines:
        for m in re.finditer(r"\bsr3d ([a-z-]+)([^&;]*)", ln):
            calls.append((m.group(1), re.findall(r"(--[a-z-]+)", m.group(2))))
    return calls


def _check(calls):
    assert calls
    for command, flags in calls:
        help_text = CliRunner().invoke(cli, [command, "--help"]).output
        for flag in flags:
            assert flag in help_text, (command, flag)


def test_the_sbatch_script_uses_existing_options():
    text = (EXAMPLES / "sr3d-array.sbatch").read_text()
    assert "--shard auto" in text and "#SBATCH --array=" in text
    _check(_sr3d_calls(text))


def test_the_indexed_job_gives_shard_auto_its_count():
    doc = yaml.safe_load((EXAMPLES / "sr3d-indexed-job.yaml").read_text())
    spec = doc["spec"]
    assert spec["completionMode"] == "Indexed"
    container = spec["template"]["spec"]["containers"][0]
    env = {e["name"]: e["value"] for e in container["env"]}
    assert int(env["SR3D_SHARD_COUNT"]) == spec["completions"]
    last = spec["completions"] - 1
    assert parse_shard("auto", {"JOB_COMPLETION_INDEX": str(last), **env}) == \
        (last, spec["completions"])
    _check(_sr3d_calls(" ".join(container["args"])))
