"""Where somwidget keeps its files: `data_dir()` is $SOMWIDGET_DATA_DIR, else the platform's data directory for
somwidget (~/.local/share/somwidget on Linux, ~/Library/Application Support/somwidget on macOS,
%LOCALAPPDATA%\\somwidget on Windows). The autosaves live in its autosave/ folder, the LAN certificate beside it.
"""

from __future__ import annotations

import os
from pathlib import Path


def data_dir() -> Path:
    """$SOMWIDGET_DATA_DIR, else the platform's user data directory for somwidget."""
    if os.environ.get("SOMWIDGET_DATA_DIR"):
        return Path(os.environ["SOMWIDGET_DATA_DIR"]).expanduser()
    import platformdirs

    return Path(platformdirs.user_data_dir("somwidget", appauthor=False))


def autosave_dir() -> Path:
    return data_dir() / "autosave"
