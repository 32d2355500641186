"""The recovery fuzz run at length: a seeded generator draws one to three damages of a saved session's folder
(tests/model/autosave_damage.py, the same families as tests/model/test_recovery_fuzz.py) and checks each restart as
the test does: it starts, brings back finite weights of a saved step (the current one when no damage could touch
it), and changes or deletes no byte of the saved folder. It prints how many runs ended each way and stops at the first
failure, printing the seed and the damages that reproduce it.

    PYTHONPATH=. python benchmarks/fuzz_recovery.py --runs 5000 --seed 1
    PYTHONPATH=. python benchmarks/fuzz_recovery.py --list     # each named corruption (autosave_damage.NAMED) once
"""

from __future__ import annotations

import argparse
import collections
import logging
import os
import random
import shutil
import sys
import tempfile
import time
import traceback
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests" / "model"))

from autosave_damage import NAMED, Saved, make_saved, random_damage, recover_damaged  # noqa: E402


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=2000, help="restarts to try (default 2000)")
    parser.add_argument("--seed", type=int, default=0, help="the generator's seed (default 0)")
    parser.add_argument("--max-damages", type=int, default=3, help="damages per run, at most (default 3)")
    parser.add_argument("--list", action="store_true", help="run each named corruption once and say what it gives")
    args = parser.parse_args(argv)
    logging.disable(logging.WARNING)  # the notices of every run; a failure prints its own
    scratch = "/dev/shm" if os.access("/dev/shm", os.W_OK) else None
    root = Path(tempfile.mkdtemp(prefix="fuzz-recovery-", dir=scratch))
    os.environ["SOMWIDGET_DATA_DIR"] = str(root / "saved")
    try:
        saved = Saved.of(make_saved(root / "saved"))
        if args.list:
            return named(saved, root)
        rng = random.Random(args.seed)
        outcomes: collections.Counter = collections.Counter()
        start = time.perf_counter()
        for run in range(args.runs):
            damages = [random_damage(rng, saved.manifest) for _ in range(rng.randint(1, args.max_damages))]
            work = root / f"run-{run}"
            try:
                outcomes[recover_damaged(saved, damages, work).outcome] += 1
            except BaseException:
                print(f"run {run} (seed {args.seed}) failed with damages:", *damages, sep="\n  ")
                traceback.print_exc()
                return 1
            finally:
                shutil.rmtree(work, ignore_errors=True)
            if (run + 1) % 500 == 0:
                print(f"{run + 1} runs, {time.perf_counter() - start:.0f} s: {dict(outcomes)}", flush=True)
        elapsed = time.perf_counter() - start
        print(f"{args.runs} runs in {elapsed:.0f} s ({1000 * elapsed / max(1, args.runs):.0f} ms a run), none lost "
              f"work: {dict(sorted(outcomes.items()))}")
        return 0
    finally:
        shutil.rmtree(root, ignore_errors=True)


def named(saved: Saved, root: Path) -> int:
    """Each corruption of NAMED once: what the restart gave, the message and the notice (shortened)."""
    for i, (name, damages) in enumerate(NAMED.items()):
        result = recover_damaged(saved, damages, root / f"named-{i}")
        said = " | ".join([result.message, *result.notices]).replace(str(root), "~")
        print(f"{name}: {result.outcome}: {said[:400]}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
