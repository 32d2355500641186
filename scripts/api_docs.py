"""Write the API reference from the docstrings (pdoc): every module of somwidget, as HTML.

    .venv/bin/python scripts/api_docs.py [OUT]      (default: build/api; open OUT/index.html)

Every module is named to pdoc, since packages that declare `__all__` would otherwise hide their submodules. The pages
carry the docstrings and signatures, not the source (read it in the repository): highlighting every function's
source took two thirds of the build.
"""

from __future__ import annotations

import logging
import pkgutil
import sys
import warnings
from pathlib import Path

import pdoc
import pdoc.render

import somwidget


def modules() -> list[str]:
    """somwidget and every module under it, by dotted name."""
    return ["somwidget"] + sorted(m.name for m in pkgutil.walk_packages(somwidget.__path__, "somwidget."))


def main(argv: list[str]) -> int:
    out = Path(argv[1] if len(argv) > 1 else "build/api")
    # names only imported for the type checker (forward references) are shown as written, not errors here
    logging.getLogger("pdoc").setLevel(logging.ERROR)
    warnings.filterwarnings("ignore", message="Error parsing type annotation")
    pdoc.render.configure(show_source=False)
    pdoc.pdoc(*modules(), output_directory=out)
    print(f"API reference: {out / 'index.html'}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
