"""Damage done to a stopped session's autosave folder, for the recovery fuzz test (test_recovery_fuzz.py) and its
longer run (benchmarks/fuzz_recovery.py).

`make_saved(root)` leaves a stopped session's folder with steps of every kind (two meshes' starts, undo and redo
steps, a radial group, a stroke, radii, settings). A `Damage` is one change a full disk, a crash, a person or an
adversary could make to such a folder, described by plain data (hypothesis prints and shrinks it): a field of the
manifest set to an adversarial value, deleted or added; the manifest's text cut, flipped or replaced; an array of a
step or preset file scaled past the engine's bounds, given a NaN, another type or shape, a member taken out or added;
a file cut short, filled with random bytes, replaced by a folder, a link (inside, outside, dangling, a loop), a named
pipe, or removed; the lock a folder or a link; stray files. `snapshot(folder)` is every entry's kind and bytes, to
show that recovery changed no byte of the folder.
"""

from __future__ import annotations

import hashlib
import io
import json
import os
import random
import shutil
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple

import numpy as np

ORIGIN = "fuzz"
#: Adversarial JSON values for any field of a manifest.
VALUES = (None, True, False, 0, -1, 1, 7, 2**31, 10**30, -(10**30), 10**400, 0.5, -0.5, 1e300, -1e300, float("nan"),
          float("inf"), float("-inf"), 1e-320, "", "x" * 300, "../../../etc/passwd", "/etc/passwd", "s1.npz", "p1.npz",
          "manifest.json", "lock", "none", "radial-99-z", "mirror-q", [], [0], [1.0, float("inf")], [None] * 3,
          ["a", "b"], {}, {"kind": "radial", "axis": 2, "n": 1000}, {"a": 1}, [[[[]]]])
#: Changes to the manifest's text.
TEXT = ("cut", "flip", "garbage", "empty", "nested", "list", "string", "utf16", "nul")
#: Changes to one array of a step or preset file.
ARRAY = ("scale1e30", "scale1e20", "nan", "inf", "ninf", "float64", "int32", "float16", "object", "transpose",
         "extra_row", "drop_col", "flat", "scalar", "empty", "drop_member", "extra_member", "rename_member",
         "negate", "zero", "fortran")
#: Those of them that may leave valid values (another state, read as it is).
VALID = ("negate", "zero", "fortran")
#: Changes to one file, whatever it holds.
FILE = ("cut", "random", "flip", "empty", "folder", "link_outside", "link_inside", "link_dangling", "link_loop",
        "fifo", "delete", "sparse_huge", "npy_not_npz", "pickle", "zip_bomb_header")
#: Changes to the folder itself.
FOLDER = ("lock_folder", "lock_link", "lock_fifo", "lock_missing", "stray_step", "stray_long", "tmp_file",
          "manifest_link", "subfolder", "manifest_fifo")


@dataclass(frozen=True)
class Damage:
    """One change to a saved session's folder (see the module's docstring): `kind` is "set", "delete", "add", "text",
    "array", "file" or "folder"; `where` a path in the manifest (keys and indices) or a file's role ("current",
    "undo:0", "redo:0", "preset:0", "manifest"); `how` what is done; `value` the value set, `n` a number that picks a
    position, a seed or a member."""

    kind: str
    where: tuple = ()
    how: str = ""
    value: object = None
    n: int = 0

    def may_hit_current(self, manifest: dict) -> bool:
        """Whether this change could make the current step unreadable (conservatively)."""
        if self.kind in ("set", "delete", "add"):
            return not self.where or self.where[0] in ("current", "format", "presets", "origin")
        if self.kind == "text":
            return True
        if self.kind == "folder":
            return self.how.startswith("lock") or self.how.startswith("manifest")
        role = self.where[0] if self.where else ""
        if role in ("current", "manifest"):
            return True
        if role.startswith("preset:"):
            names = sorted(manifest["presets"])
            return names[int(role.split(":")[1]) % len(names)] == manifest["current"]["preset"]
        return False


def make_saved(root: Path) -> Path:
    """A stopped session's folder (origin ORIGIN) under `root`/autosave with every kind of step; returns its path.
    SOMWIDGET_DATA_DIR must be `root` while it runs."""
    from somwidget.frontend.model import Session

    assert os.environ["SOMWIDGET_DATA_DIR"] == str(root)
    s = Session("sphere", device="cpu", start=False, origin=ORIGIN)
    try:
        s.move_control(1, s.controls[1, :3] + np.float32([0.1, 0.0, 0.2]))
        s.settings.set("reach", 0.2)
        s.set_control_radius(2, 0.3)
        s.settings.set_symmetry("radial-3-z")
        s.add_stroke([[0.0, 0.0, 1.2], [0.3, 0.1, 1.1], [0.5, 0.2, 0.9]], radius=0.1)
        s.load_preset("torus")
        s.move_control(0, s.controls[0, :3] + 0.15)
        s.settings.set("smoothing", 0.1)
        assert s.undo()  # one redo step
        assert s.autosave.flush(60), s.save_error
    finally:
        s.close()
    return s.autosave.path


def snapshot(folder: Path) -> dict:
    """Every entry under `folder` (not following links): relative path -> ("file", bytes) | ("dir",) | ("link",
    target) | ("other",)."""
    out = {}
    for dirpath, dirnames, filenames in os.walk(folder, followlinks=False):
        for name in dirnames + filenames:
            path = Path(dirpath) / name
            rel = str(path.relative_to(folder))
            if path.is_symlink():
                out[rel] = ("link", os.readlink(path))
            elif path.is_dir():
                out[rel] = ("dir",)
            elif path.is_file():
                out[rel] = ("file", path.read_bytes() if path.stat().st_size < (1 << 20) else _sha(path))
            else:
                out[rel] = ("other",)
    return out


def _sha(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        while chunk := f.read(1 << 22):
            h.update(chunk)
    return h.hexdigest()


def same_folder(before: dict, after: dict) -> bool:
    """No byte changed, nothing removed: `after` is `before`, plus at most an empty lock file made to lock it."""
    extra = set(after) - set(before)
    return all(after.get(k) == v for k, v in before.items()) and extra <= {"lock"} and \
        all(after[k] == ("file", b"") for k in extra)


def file_of(folder: Path, manifest: dict, role: str) -> Path:
    """The file a role names: "manifest", "current", "undo:i", "redo:i" (i taken modulo the stack; the current step
    when it is empty), "preset:i"."""
    if role == "manifest":
        return folder / "manifest.json"
    kind, _, index = role.partition(":")
    if kind == "preset":
        names = sorted(manifest["presets"])
        return folder / names[int(index) % len(names)]
    stack = manifest.get(kind) if kind in ("undo", "redo") else None
    record = stack[int(index) % len(stack)] if stack else manifest["current"]
    return folder / record["file"]


def nodes(manifest, prefix: tuple = ()) -> list[tuple]:
    """Every path (keys and indices) into `manifest`, the root's children first."""
    out = []
    items = manifest.items() if isinstance(manifest, dict) else enumerate(manifest) if isinstance(manifest, list) \
        else ()
    for key, value in items:
        out.append((*prefix, key))
        out.extend(nodes(value, (*prefix, key)))
    return out


def apply(folder: Path, damage: Damage, outside: Path, manifest: dict) -> None:
    """Make `damage` to the folder (`outside`: a folder beside it for what links point to; `manifest`: the folder's
    manifest before any damage, which names its files)."""
    manifest_path = folder / "manifest.json"
    if damage.kind in ("set", "delete", "add"):
        if not manifest_path.is_file() or manifest_path.is_symlink():
            return  # an earlier damage replaced it
        _edit_manifest(manifest_path, json.loads(manifest_path.read_text(encoding="utf-8")), damage)
    elif damage.kind == "text":
        _damage_text(manifest_path, damage)
    elif damage.kind == "array":
        _damage_array(file_of(folder, manifest, damage.where[0]), damage)
    elif damage.kind == "file":
        _damage_file(folder, file_of(folder, manifest, damage.where[0]), damage, outside)
    elif damage.kind == "folder":
        _damage_folder(folder, damage, outside)
    else:  # pragma: no cover
        raise ValueError(damage.kind)


def _edit_manifest(path: Path, manifest: dict, damage: Damage) -> None:
    *parents, last = damage.where
    node = manifest
    for key in parents:
        node = node[key]
    if damage.kind == "set":
        node[last] = damage.value
    elif damage.kind == "delete":
        del node[last]
    else:
        target = node[last]
        if isinstance(target, dict):
            target["unknown_" + str(damage.n)] = damage.value
        elif isinstance(target, list):
            target.append(damage.value)
        else:
            node[last] = [target, damage.value]
    path.write_text(json.dumps(manifest), encoding="utf-8")  # NaN and Infinity as JSON's extensions write them


def _damage_text(path: Path, damage: Damage) -> None:
    if not path.is_file() or path.is_symlink():
        return  # an earlier damage replaced it
    data = path.read_bytes()
    rng = random.Random(damage.n)
    how = damage.how
    if how == "cut":
        data = data[: damage.n % max(1, len(data))]
    elif how == "flip" and data:
        i = damage.n % len(data)
        data = data[:i] + bytes([data[i] ^ 0x5A]) + data[i + 1:]
    elif how == "garbage":
        data = rng.randbytes(1 + damage.n % 4000)
    elif how == "empty":
        data = b""
    elif how == "nested":
        data = b"[" * (10_000 + damage.n) + b"]" * (10_000 + damage.n)
    elif how == "list":
        data = b"[" + data + b"]"
    elif how == "string":
        data = json.dumps(data.decode()).encode()
    elif how == "utf16":
        data = data.decode().encode("utf-16")
    elif how == "nul":
        data = data.replace(b'"', b"\x00", 1 + damage.n % 5)
    path.write_bytes(data)


def _damage_array(path: Path, damage: Damage) -> None:
    if not path.is_file() or path.is_symlink():
        return  # an earlier damage replaced it
    with np.load(path, allow_pickle=False) as z:
        arrays = {k: z[k] for k in z.files}
    names = sorted(arrays)
    key = names[damage.n % len(names)]
    a = arrays[key]
    how = damage.how
    numeric = a.dtype.kind in "fiub" and a.size
    if how in ("scale1e30", "scale1e20") and numeric:
        with np.errstate(over="ignore", invalid="ignore"):  # float16 overflows to inf: a damage as good as any
            arrays[key] = (a.astype(np.float64) * float(how[5:]) + float(how[5:])).astype(
                a.dtype if a.dtype.kind == "f" else np.float64)
    elif how in ("nan", "inf", "ninf") and numeric:
        b = a.astype(np.float32 if a.dtype.kind != "f" else a.dtype).copy()
        b.flat[damage.n % b.size] = {"nan": np.nan, "inf": np.inf, "ninf": -np.inf}[how]
        arrays[key] = b
    elif how in ("float64", "int32", "float16"):
        with np.errstate(all="ignore"):
            arrays[key] = a.astype(how) if a.dtype.kind != "U" else np.zeros(3, how)
    elif how == "object":
        arrays[key] = np.array([None, 1, "x"], dtype=object)
    elif how == "transpose":
        arrays[key] = a.T.copy() if a.ndim == 2 else a[None]
    elif how == "extra_row":
        arrays[key] = np.concatenate([a, a[:1]]) if a.ndim >= 1 and len(a) else np.zeros(1)
    elif how == "drop_col":
        arrays[key] = a[:, :-1] if a.ndim == 2 else a[:-1]
    elif how == "flat":
        arrays[key] = a.ravel()
    elif how == "scalar":
        arrays[key] = np.float32(1.0)
    elif how == "empty":
        arrays[key] = a[:0]
    elif how == "drop_member":
        del arrays[key]
    elif how == "extra_member":
        arrays["extra"] = np.zeros(3)
    elif how == "rename_member":
        arrays["x" + key] = arrays.pop(key)
    elif how == "negate" and numeric:
        arrays[key] = -a
    elif how == "zero" and numeric:
        arrays[key] = np.zeros_like(a)
    elif how == "fortran" and a.ndim == 2:
        arrays[key] = np.asfortranarray(a)
    buffer = io.BytesIO()
    if how == "object":
        _savez_pickled(buffer, arrays)
    else:
        np.savez(buffer, **arrays)
    path.write_bytes(buffer.getvalue())


def _savez_pickled(buffer, arrays: dict) -> None:
    with zipfile.ZipFile(buffer, "w") as z:
        for k, v in arrays.items():
            member = io.BytesIO()
            np.save(member, v, allow_pickle=True)
            z.writestr(k + ".npy", member.getvalue())


def _damage_file(folder: Path, path: Path, damage: Damage, outside: Path) -> None:
    rng = random.Random(damage.n)
    how = damage.how
    if path.is_symlink() or (path.exists() and not path.is_file()):  # an earlier damage replaced it: replace that
        shutil.rmtree(path) if path.is_dir() and not path.is_symlink() else path.unlink()
    data = path.read_bytes() if path.is_file() else b""
    if how in ("folder", "link_outside", "link_inside", "link_dangling", "link_loop", "fifo", "delete"):
        path.unlink(missing_ok=True)
    if how == "cut":
        path.write_bytes(data[: damage.n % max(1, len(data))])
    elif how == "random":
        path.write_bytes(rng.randbytes(1 + damage.n % 20000))
    elif how == "flip":
        b = bytearray(data)
        for _ in range(1 + damage.n % 8):
            if b:
                b[rng.randrange(len(b))] ^= 1 << rng.randrange(8)
        path.write_bytes(bytes(b))
    elif how == "empty":
        path.write_bytes(b"")
    elif how == "folder":
        path.mkdir()
        (path / "inside").write_bytes(data[:100])
    elif how == "link_outside":
        target = outside / f"copy-{path.name}"
        target.write_bytes(data)  # a good file, but not the folder's own
        path.symlink_to(target)
    elif how == "link_inside":
        others = sorted(p for p in folder.glob("*.npz") if p != path and not p.is_symlink())
        path.symlink_to(others[damage.n % len(others)].name if others else "manifest.json")
    elif how == "link_dangling":
        path.symlink_to(outside / "nothing-here")
    elif how == "link_loop":
        path.symlink_to(path.name)
    elif how == "fifo":
        os.mkfifo(path)
    elif how == "sparse_huge":
        with open(path, "r+b") as f:
            f.truncate(256 << 20)  # 256 MiB, no blocks: more than a manifest or a step holds
    elif how == "npy_not_npz":
        buffer = io.BytesIO()
        np.save(buffer, np.zeros((4, 3), np.float32))
        path.write_bytes(buffer.getvalue())
    elif how == "pickle":
        import pickle

        path.write_bytes(pickle.dumps({"weights": [1, 2, 3]}))
    elif how == "zip_bomb_header":  # an array header that declares far more values than the member holds
        buffer = io.BytesIO()
        with zipfile.ZipFile(buffer, "w") as z:
            for name in ("weights", "controls", "radii"):
                header = io.BytesIO()
                np.lib.format.write_array_header_1_0(header, {"descr": "<f4", "fortran_order": False,
                                                              "shape": (1 << 28, 3)})
                z.writestr(name + ".npy", header.getvalue() + b"\0" * 64)
        path.write_bytes(buffer.getvalue())


def _damage_folder(folder: Path, damage: Damage, outside: Path) -> None:
    how, lock = damage.how, folder / "lock"
    if how.startswith("lock"):
        lock.unlink(missing_ok=True)
    if how == "lock_folder":
        lock.mkdir()
    elif how == "lock_link":
        lock.symlink_to(outside / "a-lock-elsewhere")
    elif how == "lock_fifo":
        os.mkfifo(lock)
    elif how == "stray_step":
        (folder / "s999999999999.npz").write_bytes(b"stray")
    elif how == "stray_long":
        (folder / ("s" + "9" * 200 + ".npz")).write_bytes(b"stray")
    elif how == "tmp_file":
        (folder / ".tmp-manifest.json-0badcafe").write_bytes(b"{")
    elif how == "manifest_link":
        target = outside / "manifest-copy.json"
        shutil.copy(folder / "manifest.json", target)
        (folder / "manifest.json").unlink()
        (folder / "manifest.json").symlink_to(target)
    elif how == "subfolder":
        (folder / "s1.npz.d").mkdir()
        (folder / "p7.npz").mkdir()
    elif how == "manifest_fifo":
        (folder / "manifest.json").unlink()
        os.mkfifo(folder / "manifest.json")


@dataclass(frozen=True)
class Saved:
    """The undamaged folder and what it holds: its manifest, the digest of every step's weights, and the current
    step's weights digest and controls."""

    folder: Path
    manifest: dict
    digests: frozenset
    current: str
    controls: np.ndarray

    @classmethod
    def of(cls, folder: Path) -> Saved:
        manifest = json.loads((folder / "manifest.json").read_text(encoding="utf-8"))
        digests = {}
        for record in [manifest["current"], *manifest["undo"], *manifest["redo"]]:
            with np.load(folder / record["file"]) as z:
                digests[record["file"]] = digest(z["weights"])
        with np.load(folder / manifest["current"]["file"]) as z:
            controls = z["controls"]
        return cls(folder, manifest, frozenset(digests.values()), digests[manifest["current"]["file"]], controls)


class Result(NamedTuple):
    """What a restart did: `outcome` "whole" (read in place), "partial" (set aside, every step back), "back-N" (the
    step N before the current one back), "nothing" (set aside, a new session) or "untouched" (not read: left as it
    is); the recovered message and the notices."""

    outcome: str
    message: str
    notices: list


def digest(weights) -> str:
    return hashlib.sha256(np.ascontiguousarray(weights, np.float32).tobytes()).hexdigest()


def recover_damaged(saved: Saved, damages, work: Path) -> str:
    """Copy the saved folder into `work` (a fresh data folder), make `damages`, start as a restart does
    (Session.recover, in this process) and check what must hold whatever the damage: the start succeeds; a session
    brought back has finite weights and controls and is one of the saved steps (the current one, when no damage could
    touch it); no byte of the saved folder is changed or deleted (it is where it was, or set aside whole), and what
    came back of a folder set aside is in a new folder that reads back whole. Returns what happened (`Result`)."""
    from somwidget.frontend.model import Session
    from somwidget.frontend.model.readback import read_folder
    from somwidget.frontend.model.recovery import recover

    folder = work / "autosave" / saved.folder.name
    outside = work / "outside"
    outside.mkdir(parents=True)
    shutil.copytree(saved.folder, folder, symlinks=True)
    for damage in damages:
        try:
            apply(folder, damage, outside, saved.manifest)
        except Exception:  # noqa: BLE001 - an earlier damage took away what this one changes (an empty file...)
            pass
    before = snapshot(folder) if folder.is_dir() else None
    old = os.environ.get("SOMWIDGET_DATA_DIR")
    os.environ["SOMWIDGET_DATA_DIR"] = str(work)
    try:
        session, notices = recover(Session, ORIGIN, device="cpu", start=False)  # as `somwidget serve` starts
        try:
            outcome = _check_session(session, saved, damages)
            new_folder = session.autosave.path if session is not None else None
            said = (session.recovered["message"] if session is not None else "", list(notices))
        finally:
            if session is not None:
                session.close()
    finally:
        if old is None:
            del os.environ["SOMWIDGET_DATA_DIR"]
        else:
            os.environ["SOMWIDGET_DATA_DIR"] = old
    aside = [p for p in folder.parent.iterdir() if p.name.startswith(folder.name + ".unreadable")]
    if before is None:
        return Result(outcome, *said)
    if folder.exists() or folder.is_symlink():
        assert not aside, aside
        assert same_folder(before, snapshot(folder)), "the saved folder was changed"
        if session is not None:
            _saves_again(work)
        return Result(outcome if session is not None else "untouched", *said)
    assert len(aside) == 1, sorted(p.name for p in folder.parent.iterdir())
    assert same_folder(before, snapshot(aside[0])), "the folder set aside is not the saved folder, whole"
    assert any(str(aside[0]) in notice for notice in notices), "a folder set aside without a notice saying where"
    if session is not None and new_folder != folder:
        assert read_folder(new_folder, 1 << 20).whole, "what came back is not whole in its new folder"
    return Result(outcome, *said)


def _saves_again(work: Path) -> None:
    """A session brought back in place goes on saving there: its next step is on disk, and the folder reads back
    whole (what was read can be written again)."""
    from somwidget.frontend.model import Session
    from somwidget.frontend.model.readback import read_folder

    old = os.environ.get("SOMWIDGET_DATA_DIR")
    os.environ["SOMWIDGET_DATA_DIR"] = str(work)
    try:
        session = Session.recover(origin=ORIGIN, device="cpu", start=False)
        try:
            session.settings.set("l_start", 0.2 if session.parameters["l_start"] != 0.2 else 0.3)
            assert session.autosave.flush(30), session.save_error
            assert read_folder(session.autosave.path, 1 << 20).whole
        finally:
            session.close()
    finally:
        if old is None:
            del os.environ["SOMWIDGET_DATA_DIR"]
        else:
            os.environ["SOMWIDGET_DATA_DIR"] = old


def _check_session(session, saved: Saved, damages) -> str:
    if session is None:
        assert any(d.may_hit_current(saved.manifest) for d in damages), "nothing came back of an intact current step"
        return "nothing"
    snap = session.files.snapshot()
    weights, controls = snap["weights"], snap["controls"]
    assert np.isfinite(weights).all() and np.isfinite(controls).all()
    assert np.isfinite(session.frame.positions).all()
    if not any(d.kind == "array" and d.how in VALID for d in damages):
        assert digest(weights) in saved.digests, "the session brought back is none of the saved steps"
    if not any(d.may_hit_current(saved.manifest) for d in damages):
        assert digest(weights) == saved.current, "the current step could be read but did not come back"
        np.testing.assert_array_equal(controls, saved.controls)
    message = session.recovered["message"]
    assert message.startswith("Brought back your session"), message
    back = session.recovered.get("back", 0)
    if back:
        assert f"as it was {back} step" in message, message
        return f"back-{back}"
    return "whole" if not session.notices else "partial"


def random_damage(rng: random.Random, manifest: dict) -> Damage:
    """One damage drawn with `rng` (the longer run's generator: the same families as the test's strategy)."""
    kind = rng.choice(("set", "set", "set", "delete", "add", "text", "array", "array", "file", "file", "folder"))
    roles = ("current", "undo:0", "undo:1", "undo:3", "redo:0", "preset:0", "preset:1", "manifest")
    n = rng.randrange(1 << 20)
    if kind in ("set", "delete", "add"):
        where = rng.choice(nodes(manifest))
        return Damage(kind, where, value=rng.choice(VALUES), n=n)
    if kind == "text":
        return Damage(kind, ("manifest",), rng.choice(TEXT), n=n)
    if kind == "array":
        return Damage(kind, (rng.choice(roles[:-1]),), rng.choice(ARRAY), n=n)
    if kind == "file":
        return Damage(kind, (rng.choice(roles),), rng.choice(FILE), n=n)
    return Damage(kind, (), rng.choice(FOLDER), n=n)


def _set(*where, value) -> Damage:
    return Damage("set", where, value=value)


#: Corruptions by name (benchmarks/fuzz_recovery.py --list prints what each gives): the issue's and their kin.
NAMED: dict[str, list[Damage]] = {
    "manifest: removed": [Damage("file", ("manifest",), "delete")],
    "manifest: a folder": [Damage("file", ("manifest",), "folder")],
    "manifest: cut short": [Damage("text", ("manifest",), "cut", n=40)],
    "manifest: empty": [Damage("text", ("manifest",), "empty")],
    "manifest: random bytes": [Damage("text", ("manifest",), "garbage", n=7)],
    "manifest: UTF-16": [Damage("text", ("manifest",), "utf16")],
    "manifest: a JSON list": [Damage("text", ("manifest",), "list")],
    "manifest: 20,000 nested brackets": [Damage("text", ("manifest",), "nested")],
    "manifest: a link out of the folder": [Damage("folder", (), "manifest_link")],
    "manifest: a named pipe": [Damage("folder", (), "manifest_fifo")],
    "manifest: format 2 (a newer somwidget)": [_set("format", value=2)],
    "manifest: format \"1\"": [_set("format", value="1")],
    "manifest: presets missing": [Damage("delete", ("presets",))],
    "manifest: current step missing": [Damage("delete", ("current",))],
    "manifest: undo not a list": [_set("undo", value="s3.npz")],
    "manifest: saved 1e300": [_set("saved", value=1e300)],
    "manifest: saved NaN": [_set("saved", value=float("nan"))],
    "manifest: saved \"yesterday\"": [_set("saved", value="yesterday")],
    "manifest: gesture \"yes\"": [_set("gesture", value="yes")],
    "current step: file \"../p1.npz\"": [_set("current", "file", value="../p1.npz")],
    "current step: file names a missing s99.npz": [_set("current", "file", value="s99.npz")],
    "current step: s past S": [_set("current", "iteration", value=10**6)],
    "current step: s = -1": [_set("current", "iteration", value=-1)],
    "current step: s 10**400": [_set("current", "iteration", value=10**400)],
    "current step: reach 5 (range (0, 1])": [_set("current", "parameters", "reach", value=5)],
    "current step: Infinity in the metric weights": [_set("current", "parameters", "metric_weights", 0,
                                                          value=float("inf"))],
    "every step: Infinity in the metric weights": [_set(k, *(i,) if k != "current" else (), "parameters",
                                                        "metric_weights", 0, value=float("inf"))
                                                   for k, n in (("current", 1), ("undo", 7), ("redo", 1))
                                                   for i in range(n)],
    "current step: metric weights all 0": [_set("current", "parameters", "metric_weights", value=[0, 0, 0])],
    "current step: a setting of a newer somwidget": [Damage("add", ("current", "parameters"), value=1.0)],
    "undo step: a setting of a newer somwidget": [Damage("add", ("undo", 3, "parameters"), value=1.0)],
    "current step: radial group of 1000": [_set("current", "symmetry", value={"kind": "radial", "axis": 2,
                                                                               "n": 1000})],
    "current step: strokes do not cover the controls": [_set("current", "strokes", value=[1, 1])],
    "current step file: cut short": [Damage("file", ("current",), "cut", n=300)],
    "current step file: random bytes": [Damage("file", ("current",), "random", n=5000)],
    "current step file: a pickle": [Damage("file", ("current",), "pickle")],
    "current step file: one .npy, not an .npz": [Damage("file", ("current",), "npy_not_npz")],
    "current step file: weights x1e30": [Damage("array", ("current",), "scale1e30", n=2)],
    "current step file: controls x1e30": [Damage("array", ("current",), "scale1e30", n=0)],
    "current step file: a NaN in the weights": [Damage("array", ("current",), "nan", n=2)],
    "current step file: -Infinity in the radii": [Damage("array", ("current",), "ninf", n=1)],
    "current step file: weights float64": [Damage("array", ("current",), "float64", n=2)],
    "current step file: weights of Python objects": [Damage("array", ("current",), "object", n=2)],
    "current step file: weights a row short": [Damage("array", ("current",), "drop_col", n=2)],
    "current step file: no controls": [Damage("array", ("current",), "empty", n=0)],
    "current step file: radii negative": [Damage("array", ("current",), "negate", n=1)],
    "current step file: a member missing": [Damage("array", ("current",), "drop_member", n=1)],
    "current step file: an extra member": [Damage("array", ("current",), "extra_member")],
    "current step file: a header declaring 2^28 rows": [Damage("file", ("current",), "zip_bomb_header")],
    "current step file: a folder": [Damage("file", ("current",), "folder")],
    "current step file: a link to a good copy outside": [Damage("file", ("current",), "link_outside")],
    "current step file: a link to another step": [Damage("file", ("current",), "link_inside")],
    "current step file: a link to itself": [Damage("file", ("current",), "link_loop")],
    "current step file: a named pipe": [Damage("file", ("current",), "fifo")],
    "current step file: a sparse 256 MiB file": [Damage("file", ("current",), "sparse_huge")],
    "current step file: removed": [Damage("file", ("current",), "delete")],
    "current and newest undo step files: random bytes": [Damage("file", ("current",), "random", n=1),
                                                          Damage("file", ("undo:6",), "random", n=2)],
    "undo step file (the 3rd back): random bytes": [Damage("file", ("undo:4",), "random", n=3)],
    "redo step file: cut short": [Damage("file", ("redo:0",), "cut", n=200)],
    "presets: -Infinity among a mesh's facts (meta)": [Damage("add", ("presets", "p3.npz", "meta"),
                                                               value=float("-inf"))],
    "preset file of the current step: random bytes": [Damage("file", ("preset:0",), "random", n=9)],
    "preset file of the older steps: cut short": [Damage("file", ("preset:1",), "cut", n=500)],
    "preset file of the older steps: n_vertices 1e30": [Damage("array", ("preset:1",), "scale1e30", n=19)],
    "lock: a folder": [Damage("folder", (), "lock_folder")],
    "lock: a link out of the folder": [Damage("folder", (), "lock_link")],
    "lock: a named pipe": [Damage("folder", (), "lock_fifo")],
    "lock: removed": [Damage("folder", (), "lock_missing")],
    "stray step files s999999999999.npz and s<200 digits>.npz": [Damage("folder", (), "stray_step"),
                                                                 Damage("folder", (), "stray_long")],
    "a temporary file a kill left": [Damage("folder", (), "tmp_file")],
}
