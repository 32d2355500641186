"""Engine benchmark, no install needed: `PYTHONPATH=. python benchmarks/bench_engine.py [--device cuda] [...]`.

The same harness as `somwidget bench` (engine_harness.py, beside this file), which needs only numpy and warp-lang.
Arguments are those of `somwidget bench --help`.
"""

import os
import sys

if __name__ == "__main__":
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    if root not in sys.path:  # also works without PYTHONPATH, from any directory
        sys.path.insert(0, root)
    from somwidget.cli import main

    sys.exit(main(["bench", *sys.argv[1:]]))
