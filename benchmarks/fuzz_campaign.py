"""Fuzz campaign: thousands of mutated recordings through ``scrapcut info`` and ``scrapcut fit``.

    .venv/bin/python benchmarks/fuzz_campaign.py [--cases 1200] [--fit-every 6] [--jobs 1]
                                                 [--seed 0] [--keep DIR]

Three bases made from ``fixtures/sim_cylinder_small.mcap``: the fixture itself (zstd chunks,
CRCs), the same uncompressed in 64 KiB chunks without CRCs (nothing but the readers' own
checks between a mutation and the parser) and a ROS 1 bag. Case k mutates base k mod 3 with
``tests/recording_faults.mutate`` seeded by (seed, k): 1-3 structural mutations (records
dropped, duplicated, swapped, cut off; length, offset, count, opcode fields; strings; bytes).
Every case runs ``scrapcut info CASE --json``; every ``--fit-every``-th also ``scrapcut fit
CASE -o OUT/path.json``. Commands run in worker processes through click's test runner with
``cli.main``'s settings (the same code a shell runs, without a Python start-up per case); each
worker's address space is capped (``--memory-gb``) and a case that does not finish within its
timeout is a hang (the worker is killed and replaced).

Outcomes, counted per base and command:
  ok           exit 0 (``info`` printed JSON; ``fit`` wrote one complete path file, and its
               complete error report when the recording holds a reference)
  error        exit 1 with exactly one ``scrapcut: error:`` line on stderr, nothing written
  traceback    anything else: an uncaught exception, several lines, another exit code
  memory       a MemoryError or OverflowError anywhere, even wrapped in a one-line message
  hang         no answer within the timeout
  half-written an output folder holding anything but a complete path file (a temporary,
               an empty or truncated file)
The issue's bar: 0 traceback, 0 memory, 0 hang, 0 half-written.
"""

from __future__ import annotations

import argparse
import collections
import json
import multiprocessing as mp
import os
import shutil
import signal
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "tests"))  # recording_faults: the mutations the tests use too

from recording_faults import RandomChoices, mutate, write_bases  # noqa: E402

OUTCOMES = ("ok", "error", "traceback", "memory", "hang", "half-written")
TIMEOUT_S = {"info": 120.0, "fit": 600.0}


def _worker(conn: Any, memory_gb: float) -> None:
    """Run commands in this process until told to stop; answer (outcome, detail)."""
    import resource
    import warnings

    from click.testing import CliRunner

    from scrapcut_cli.cli import cli

    limit = int(memory_gb * (1 << 30))
    resource.setrlimit(resource.RLIMIT_AS, (limit, limit))
    warnings.simplefilter("ignore", RuntimeWarning)  # as cli.main
    runner = CliRunner()
    parent = os.getppid()
    while True:
        if not conn.poll(5.0):
            if os.getppid() != parent:  # the campaign was killed: do not linger
                return
            continue
        task = conn.recv()
        if task is None:
            return
        command, case, out_dir = task
        args = ["info", case, "--json"] if command == "info" else ["fit", case, "-o"]
        if command == "fit":
            args.append(str(Path(out_dir) / "path.json"))
        try:
            result = runner.invoke(cli, args, catch_exceptions=True)
            conn.send(_classify(command, result, out_dir))
        except MemoryError:
            conn.send(("memory", "MemoryError outside the command"))


def _classify(command: str, result: Any, out_dir: str | None) -> tuple[str, str]:
    stderr = [line for line in result.stderr.splitlines() if line.strip()]
    exc = result.exception
    if isinstance(exc, MemoryError | OverflowError) or any(
        "MemoryError" in line or "OverflowError" in line for line in stderr
    ):
        return "memory", (stderr or [repr(exc)])[-1][:300]
    if exc is not None and not isinstance(exc, SystemExit):
        return "traceback", f"{type(exc).__name__}: {exc}"[:300]
    if result.exit_code == 0:
        if command == "info":
            try:
                json.loads(result.stdout)
            except ValueError:
                return "traceback", "info --json printed no JSON"
        elif out_dir is not None:
            bad = _half_written(Path(out_dir), expect_path=True)
            if bad:
                return "half-written", bad
        return "ok", ""
    one_line = len(stderr) == 1 and stderr[0].startswith("scrapcut: error: ")
    if result.exit_code == 1 and one_line:
        if out_dir is not None:
            bad = _half_written(Path(out_dir), expect_path=False)
            if bad:
                return "half-written", bad
        return "error", stderr[0][len("scrapcut: error: ") :][:300]
    return "traceback", f"exit {result.exit_code}: {' | '.join(stderr)[:300]}"


def _half_written(folder: Path, *, expect_path: bool) -> str:
    """'' if ``folder`` holds what the outcome promises: nothing after an error; after a fit,
    one complete path file and, when the recording had a reference, its complete error report
    (``path.error.json`` and ``.md``)."""
    names = sorted(p.name for p in folder.iterdir())
    if not expect_path:
        return f"left {names}" if names else ""
    if names not in (["path.json"], ["path.error.json", "path.error.md", "path.json"]):
        return f"left {names}"
    try:
        data = json.loads((folder / "path.json").read_text())
        if "path.error.json" in names:
            json.loads((folder / "path.error.json").read_text())
            if not (folder / "path.error.md").read_text().strip():
                return "path.error.md is empty"
    except ValueError as exc:
        return f"an output is unreadable: {exc}"
    return "" if data.get("schema") == "scrapcut.path/v1" else "path.json without its schema"


class _Worker:
    def __init__(self, memory_gb: float) -> None:
        self.conn, child = mp.Pipe()
        self.process = mp.Process(target=_worker, args=(child, memory_gb), daemon=True)
        self.process.start()
        self.memory_gb = memory_gb

    def run(self, task: tuple[str, str, str | None], timeout: float) -> tuple[str, str]:
        self.conn.send(task)
        if self.conn.poll(timeout):
            try:
                return tuple(self.conn.recv())  # type: ignore[return-value]
            except EOFError:
                self.restart()
                return "traceback", "the worker process died"
        self.restart()
        return "hang", f"no answer within {timeout:.0f} s"

    def restart(self) -> None:
        self.process.kill()
        self.process.join()
        self.__init__(self.memory_gb)  # type: ignore[misc]

    def stop(self) -> None:
        self.conn.send(None)
        self.process.join(timeout=10)
        if self.process.is_alive():
            self.process.kill()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", type=int, default=1200)
    parser.add_argument("--fit-every", type=int, default=6, help="0: no fit runs")
    parser.add_argument("--jobs", type=int, default=1)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--memory-gb", type=float, default=4.0)
    parser.add_argument("--keep", type=Path, default=None, help="copy non-ok cases here")
    parser.add_argument("--source", type=Path, default=REPO / "fixtures/sim_cylinder_small.mcap")
    args = parser.parse_args()

    work = Path(tempfile.mkdtemp(prefix="scrapcut-fuzz-"))
    try:
        bases = write_bases(args.source, work / "bases")
        names = list(bases)
        raw = {name: path.read_bytes() for name, (path, _) in bases.items()}
        counts: dict[tuple[str, str], collections.Counter[str]] = collections.defaultdict(
            collections.Counter
        )
        examples: dict[tuple[str, str, str], list[str]] = collections.defaultdict(list)
        workers = [_Worker(args.memory_gb) for _ in range(max(1, args.jobs))]
        started = time.perf_counter()
        tasks = []
        for k in range(args.cases):
            name = names[k % len(names)]
            tasks.append((k, name, "info"))
            if args.fit_every and (k // len(names)) % args.fit_every == 0:  # every base
                tasks.append((k, name, "fit"))
        pending = list(tasks)
        # Round-robin over workers, one task each at a time (commands are CPU-bound).
        import threading

        lock = threading.Lock()

        def drain(worker: _Worker) -> None:
            while True:
                with lock:
                    if not pending:
                        return
                    k, name, command = pending.pop(0)
                # Written when run and removed after: 1,200 copies of the fixture are GBs.
                path, fmt = bases[name]
                case = work / f"case_{k:05d}_{command}{path.suffix}"
                case.write_bytes(mutate(raw[name], fmt, RandomChoices(args.seed * 1_000_003 + k)))
                out_dir = None
                if command == "fit":
                    out_dir = work / f"out_{k:05d}"
                    out_dir.mkdir()
                outcome, detail = worker.run(
                    (command, str(case), None if out_dir is None else str(out_dir)),
                    TIMEOUT_S[command],
                )
                detail = detail.replace(str(case), "CASE").replace(str(work), "WORK")
                with lock:
                    counts[(name, command)][outcome] += 1
                    if outcome != "ok" and len(examples[(name, command, outcome)]) < 3:
                        examples[(name, command, outcome)].append(f"case {k}: {detail}")
                    if outcome not in ("ok", "error") and args.keep is not None:
                        args.keep.mkdir(parents=True, exist_ok=True)
                        shutil.copy(case, args.keep / case.name)
                    done = sum(sum(c.values()) for c in counts.values())
                    if done % 100 == 0:
                        print(f"  {done}/{len(tasks)} runs", file=sys.stderr, flush=True)
                if out_dir is not None:
                    shutil.rmtree(out_dir, ignore_errors=True)
                case.unlink(missing_ok=True)

        threads = [threading.Thread(target=drain, args=(w,)) for w in workers]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        for w in workers:
            w.stop()
        wall = time.perf_counter() - started
    finally:
        shutil.rmtree(work, ignore_errors=True)

    from scrapcut_cli.pipeline.reproduce import machine_description

    print(f"fuzz campaign: {args.cases} mutated recordings ({len(tasks)} runs), seed {args.seed}")
    print(f"machine: {machine_description()}; {args.jobs} worker(s), {wall / 60:.1f} min")
    header = f"{'base':<11} {'command':<8}" + "".join(f"{o:>13}" for o in OUTCOMES)
    print(header)
    totals: collections.Counter[str] = collections.Counter()
    for name in names:
        for command in ("info", "fit"):
            c = counts.get((name, command))
            if not c:
                continue
            totals.update(c)
            print(f"{name:<11} {command:<8}" + "".join(f"{c[o]:>13}" for o in OUTCOMES))
    print(f"{'total':<20}" + "".join(f"{totals[o]:>13}" for o in OUTCOMES))
    for (name, command, outcome), lines in sorted(examples.items()):
        if outcome == "error":
            continue
        for line in lines:
            print(f"  {outcome} ({name} {command}) {line}")
    common = collections.Counter(
        line.split(": ", 1)[-1][:70]
        for (_, _, outcome), lines in examples.items()
        if outcome == "error"
        for line in lines
    )
    print("sample errors:", "; ".join(text for text, _ in common.most_common(6)))
    bad = sum(totals[o] for o in OUTCOMES if o not in ("ok", "error"))
    sys.exit(1 if bad else 0)


if __name__ == "__main__":
    signal.signal(signal.SIGINT, signal.default_int_handler)
    main()
