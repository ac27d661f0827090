"""Running ``manip_kin`` commands on hostile files inside a process bounded by setrlimit.

The fuzzers (``hostile_robot_files.py``, ``hostile_recordings.py``) run as scripts: they call
:func:`limit_this_process` first (RLIMIT_CPU, RLIMIT_AS), then :func:`run_cli` per file, which
arms a CPU alarm (ITIMER_PROF) so a hang on one file becomes a finding instead of a stuck
test. :func:`one_line_refusal_problem` is the rule every refusal obeys.
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import resource
import signal
import subprocess
import sys
from pathlib import Path

CPU_SECONDS = 60  # the whole process (RLIMIT_CPU); the parent's timeout is above it
CASE_CPU_SECONDS = 5  # one command (ITIMER_PROF)
ADDRESS_SPACE_BYTES = 3 << 29  # 1.5 GiB (RLIMIT_AS): the unbounded bombs took 1.1 and 2.1 GB
HERE = Path(__file__).resolve().parent


def limit_this_process() -> None:
    """Cap CPU time and address space, and turn a CPU alarm into a TimeoutError."""
    resource.setrlimit(resource.RLIMIT_CPU, (CPU_SECONDS, CPU_SECONDS))
    resource.setrlimit(resource.RLIMIT_AS, (ADDRESS_SPACE_BYTES, ADDRESS_SPACE_BYTES))

    def out_of_time(signum, frame):
        raise TimeoutError(f"more than {CASE_CPU_SECONDS} s of CPU for one command")

    signal.signal(signal.SIGPROF, out_of_time)


def run_cli(args: list[str]) -> dict:
    """``manip_kin ARGS`` in this process: ``rc`` (None when an exception escaped), ``stdout``, ``stderr``."""
    from manip_kin.cli import main

    stdout, stderr = io.StringIO(), io.StringIO()
    result: dict = {"args": args}
    signal.setitimer(signal.ITIMER_PROF, CASE_CPU_SECONDS)
    try:
        with contextlib.redirect_stdout(stdout), contextlib.redirect_stderr(stderr):
            result["rc"] = main(args)
    except BaseException as error:  # noqa: BLE001 - what escapes the CLI is the finding
        result["rc"] = None
        result["escaped"] = f"{type(error).__name__}: {str(error)[:300]}"
    finally:
        signal.setitimer(signal.ITIMER_PROF, 0)
    result["stdout"], result["stderr"] = stdout.getvalue()[:200_000], stderr.getvalue()[:4000]
    return result


def one_line_refusal_problem(result: dict, must_name: str) -> str | None:
    """Why an exit-2 result breaks the rule (one stderr line naming ``must_name``), or None."""
    if result["rc"] is None:
        return f"escaped the CLI: {result['escaped']}"
    if result["rc"] != 2:
        return f"exit {result['rc']}, not 2: {result['stderr'][:500]}"
    lines = result["stderr"].strip().splitlines()
    if len(lines) != 1:
        return f"stderr is {len(lines)} lines, not one: {result['stderr'][:800]}"
    if must_name not in lines[0]:
        return f"the error does not name {must_name}: {lines[0]}"
    return None


class Outcomes(dict):
    """A fuzzer's results by case; a case it never reached fails with why the process ended."""

    died = ""

    def __missing__(self, case: str):
        raise AssertionError(f"no result for {case!r}: the bounded process ended before it ({self.died})")


def save_progress(out: str | Path, results: dict) -> None:
    """Write the results so far (a fuzzer killed by its limits still reports the cases it finished)."""
    Path(out).write_text(json.dumps(results))


def first_failure(check) -> str | None:
    """Run a hypothesis test function; its failure (the falsifying example) as text, or None."""
    try:
        check()
    except AssertionError as error:
        return str(error)[:3000]
    return None


def run_bounded_script(script: str, out: Path, *args: str) -> Outcomes:
    """Run ``test/SCRIPT OUT ARGS`` (a fuzzer) and return the JSON it wrote to OUT, even a partial one."""
    path = os.pathsep.join(p for p in (str(HERE), os.environ.get("PYTHONPATH", "")) if p)
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1", "PYTHONPATH": path, "MPLBACKEND": "Agg"}
    completed = subprocess.run(
        [sys.executable, str(HERE / script), str(out), *args],
        env=env,
        capture_output=True,
        text=True,
        timeout=CPU_SECONDS * 3,
    )
    outcomes = Outcomes(json.loads(out.read_text()) if out.is_file() else {})
    if completed.returncode != 0:
        signal_name = signal.Signals(-completed.returncode).name if completed.returncode < 0 else ""
        outcomes.died = f"exit {completed.returncode} {signal_name}: {completed.stderr[-2000:]}"
    return outcomes
