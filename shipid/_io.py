"""Small I/O helpers: atomic writes that never clobber a user's file, strict JSON,
guarded JSON/YAML reading, hashes and one-line error text.

Writing
    :func:`atomic_write_bytes` writes a temporary file in the destination folder
    and then *links* it to the destination (``os.link`` fails if the name exists,
    so two writers racing for one name cannot both win: the loser gets
    :class:`OutputExistsError`); with ``force=True`` it renames over the old file.
    :func:`atomic_write_set` writes several files (e.g. a plan's JSON and CSV)
    as a set: all temporaries first, then the links in quick succession, rolled
    back if any fails.  Temporaries of a run killed by SIGTERM/SIGHUP/SIGINT are
    removed by :func:`install_signal_cleanup` (the CLI installs it); SIGKILL
    cannot be caught, so a ``.NAME.*.tmp`` may survive that.
    :func:`dumps_json` is the one JSON writer: strict JSON (``NaN``/``inf`` become
    ``null``, numpy scalars and arrays become numbers and lists).

Reading
    :func:`read_json` / :func:`loads_yaml` refuse files that are too large or
    nested too deeply with one line naming the file.  Schema checks are
    hand-written (:func:`check_keys`, :func:`as_number`, ...) rather than a
    validator such as ``jsonschema``: no extra dependency, and every message is
    short, names the key path, and never echoes a huge value back.
"""
from __future__ import annotations

import atexit
import hashlib
import importlib.util
import json
import math
import os
import signal
import stat
import tempfile
from pathlib import Path

import numpy as np

__all__ = ["atomic_write_bytes", "atomic_write_text", "atomic_write_set", "sha256_file", "OutputExistsError",
           "dumps_json", "to_jsonable", "read_json", "loads_yaml", "short", "check_keys", "as_number", "as_int",
           "as_mapping", "as_string", "as_bool", "check_output_path", "install_signal_cleanup", "MAX_DEPTH",
           "check_memory", "memory_limit_bytes", "loads_json", "restore_signal_handlers",
           "MAX_FILE_BYTES", "read_structured", "MAX_YAML_BYTES", "MAX_ALIASES",
           "MAX_EXPANDED_NODES", "check_output_target"]

#: Deepest nesting accepted in a JSON/YAML file the program reads.
MAX_DEPTH = 64
#: Largest JSON/YAML file accepted (bytes).
MAX_FILE_BYTES = 64 * 1024 * 1024

_LIVE_TMP: set[str] = set()


class OutputExistsError(ValueError):
    """Raised when an output file exists and overwriting was not allowed."""


def short(value, limit: int = 60) -> str:
    """``repr(value)`` cut to ``limit`` characters (error messages never echo a 100 kB value)."""
    text = repr(value)
    return text if len(text) <= limit else text[: limit - 5] + "...'" + f" ({len(text)} chars)"


def _exists_message(path: Path) -> str:
    return f"{path}: output exists; choose another name or pass --force (force=True) to overwrite it"


_KINDS = {stat.S_IFIFO: "a FIFO (named pipe)", stat.S_IFCHR: "a character device", stat.S_IFBLK: "a block device",
          stat.S_IFSOCK: "a socket", stat.S_IFDIR: "a folder"}


def check_output_target(path, what: str = "output") -> None:
    """ValueError when ``path`` exists and is not a regular file or a symbolic link (its own entry is what
    ``--force`` replaces): a folder, FIFO, device or socket is never replaced by an output, even with
    ``--force`` (``-o /dev/null --force`` run as root would otherwise replace the system's /dev/null)."""
    try:
        mode = os.lstat(path).st_mode
    except (FileNotFoundError, NotADirectoryError):
        return
    if stat.S_ISREG(mode) or stat.S_ISLNK(mode):
        return
    kind = _KINDS.get(stat.S_IFMT(mode), "not a regular file")
    raise ValueError(f"{path}: is {kind}; the {what} is written as a regular file only (never over a device, "
                     "pipe, socket or folder, even with --force); give a file name")


def check_output_path(path, *, force: bool = False, inputs=(), what: str = "output") -> Path:
    """Check an output name *before* a long computation.

    ValueError when the name is empty or a folder, when it is one of ``inputs``,
    when it exists without ``force``, when its folder is missing, or when the
    folder is not writable.  Returns the path.
    """
    if path is None or str(path).strip() == "":
        raise ValueError(f"{what}: empty file name; give a file name, e.g. -o result.json")
    p = Path(path)
    if p.is_dir():
        raise ValueError(f"{p}: is a folder; give a file name for the {what}")
    check_output_target(p, what)
    rp = p.resolve()
    for q in inputs:
        if q is not None and Path(q).exists() and Path(q).resolve() == rp:
            raise ValueError(f"{p}: the {what} would replace the input file {q}; choose another name")
    if (p.exists() or p.is_symlink()) and not force:
        raise OutputExistsError(_exists_message(p))
    folder = p.parent
    if not folder.exists():
        raise ValueError(f"{p}: folder {folder} does not exist; create it first")
    if not os.access(folder, os.W_OK | os.X_OK):
        raise ValueError(f"{p}: folder {folder} is not writable; choose another folder or fix its permissions")
    return p


def _tmp_for(path: Path) -> str:
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    except PermissionError:
        raise PermissionError(f"{path}: cannot write in folder {path.parent} (permission denied); "
                              "choose another folder") from None
    os.close(fd)
    _LIVE_TMP.add(tmp)
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp, 0o666 & ~umask)  # mkstemp creates 0600; give the file ordinary permissions
    return tmp


def _fill(tmp: str, data: bytes) -> None:
    with open(tmp, "wb") as fh:
        fh.write(data)
        fh.flush()
        os.fsync(fh.fileno())


def _drop(tmp: str) -> None:
    _LIVE_TMP.discard(tmp)
    try:
        os.unlink(tmp)
    except FileNotFoundError:
        pass


def _publish(tmp: str, path: Path, force: bool) -> None:
    """Move ``tmp`` to ``path``: rename with ``force``, else create ``path`` exclusively (hard link)."""
    if force:
        check_output_target(path)  # again just before the rename: the name may have changed since the check
        os.replace(tmp, path)
        _LIVE_TMP.discard(tmp)
        return
    try:
        os.link(tmp, path)
    except FileExistsError:
        raise OutputExistsError(_exists_message(path)) from None
    except OSError:  # a file system without hard links: reserve the name exclusively, then rename over it
        try:
            os.close(os.open(path, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o666))
        except FileExistsError:
            raise OutputExistsError(_exists_message(path)) from None
        os.replace(tmp, path)
    _drop(tmp)


def atomic_write_set(items, *, force: bool = False) -> list[Path]:
    """Write several files as a set: ``items`` is a list of ``(path, bytes | str)``.

    Every file is first written to a temporary beside its destination; then the
    temporaries are published one after the other (exclusively unless
    ``force``).  If any step fails, the files already published by this call
    are removed again, so a rerun is not blocked by half a set.
    """
    items = [(Path(p), d.encode("utf-8") if isinstance(d, str) else bytes(d)) for p, d in items]
    for p, _ in items:
        if str(p).strip() in ("", "."):
            raise ValueError("output: empty file name; give a file name, e.g. -o result.json")
        check_output_target(p)
        if p.exists() and not force:
            raise OutputExistsError(_exists_message(p))
        if not p.parent.exists():
            raise ValueError(f"{p}: folder {p.parent} does not exist; create it first")
    tmps: list[str] = []
    done: list[Path] = []
    try:
        for p, d in items:
            tmps.append(_tmp_for(p))
            _fill(tmps[-1], d)
        for (p, _), tmp in zip(items, tmps):
            _publish(tmp, p, force)
            done.append(p)
    except BaseException:
        for tmp in tmps:
            _drop(tmp)
        if not force:  # remove what this call created (with force the old files are already replaced)
            for p in done:
                try:
                    os.unlink(p)
                except FileNotFoundError:
                    pass
        raise
    return [p for p, _ in items]


def atomic_write_bytes(path: str | os.PathLike, data: bytes, *, force: bool = False) -> Path:
    """Write ``data`` to ``path`` atomically (temporary file in the same folder, then link or rename).

    An existing file is replaced only with ``force=True``; otherwise
    :class:`OutputExistsError` names it and says to pass ``--force`` -- also
    when another writer creates the file while this one is writing.
    """
    return atomic_write_set([(path, data)], force=force)[0]


def atomic_write_text(path: str | os.PathLike, text: str, *, force: bool = False) -> Path:
    """Text version of :func:`atomic_write_bytes` (UTF-8)."""
    return atomic_write_bytes(path, text.encode("utf-8"), force=force)


def _cleanup_tmp() -> None:
    for tmp in list(_LIVE_TMP):
        _drop(tmp)


_ATEXIT = []


def install_signal_cleanup() -> dict:
    """On SIGTERM/SIGHUP remove this process's temporaries and exit with 128 + signal number.

    (SIGINT already raises KeyboardInterrupt, which the writers clean up after.)
    Returns the previous handlers for :func:`restore_signal_handlers`.
    """
    def handler(signum, frame):
        _cleanup_tmp()
        raise SystemExit(128 + signum)

    previous = {}
    for sig in (signal.SIGTERM, getattr(signal, "SIGHUP", None)):
        if sig is not None:
            try:
                previous[sig] = signal.signal(sig, handler)
            except (ValueError, OSError):  # not the main thread
                break
    if not _ATEXIT:
        atexit.register(_cleanup_tmp)
        _ATEXIT.append(True)
    return previous


def restore_signal_handlers(previous: dict) -> None:
    """Put back the handlers :func:`install_signal_cleanup` replaced."""
    for sig, h in previous.items():
        try:
            signal.signal(sig, h if h is not None else signal.SIG_DFL)
        except (ValueError, OSError):
            pass


def to_jsonable(obj):
    """Plain-Python copy of ``obj`` for strict JSON: non-finite floats -> None, numpy -> Python."""
    if isinstance(obj, dict):
        return {str(k): to_jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [to_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return to_jsonable(obj.tolist())
    if isinstance(obj, (bool, np.bool_)):
        return bool(obj)
    if isinstance(obj, (int, np.integer)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        v = float(obj)
        return v if math.isfinite(v) else None
    if isinstance(obj, os.PathLike):
        return os.fspath(obj)
    return obj


def dumps_json(obj, *, indent: int | None = 2) -> str:
    """The one JSON writer: strict JSON text (no NaN/Infinity tokens) ending in a newline."""
    return json.dumps(to_jsonable(obj), indent=indent, allow_nan=False) + "\n"


def _depth_ok(doc, max_depth: int) -> bool:
    stack = [(doc, 1)]
    while stack:
        node, d = stack.pop()
        if isinstance(node, (dict, list)):
            if d > max_depth:
                return False
            stack.extend((v, d + 1) for v in (node.values() if isinstance(node, dict) else node))
    return True


def _read_text(path: Path, what: str) -> str:
    if not path.exists():
        if path.is_symlink():
            raise FileNotFoundError(f"{path}: a symbolic link to a missing file or a loop of links "
                                    f"({short(os.readlink(path), 60)}); give the {what} file itself")
        raise FileNotFoundError(f"{path}: no such {what} file; check the path")
    if path.is_dir():
        raise ValueError(f"{path}: is a folder, not a {what} file")
    if not path.is_file():
        raise ValueError(f"{path}: not a regular file (a pipe or device?); give a {what} file")
    size = path.stat().st_size
    if size > MAX_FILE_BYTES:
        raise ValueError(f"{path}: {size / 2**20:.0f} MiB is too large for a {what} file "
                         f"(limit {MAX_FILE_BYTES // 2**20} MiB)")
    try:
        with open(path, "rb") as fh:  # at most the limit, even if the file grows after the check
            data = fh.read(MAX_FILE_BYTES + 1)
        if len(data) > MAX_FILE_BYTES:
            raise ValueError(f"{path}: more than {MAX_FILE_BYTES // 2**20} MiB; too large for a {what} file")
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ValueError(f"{path}: not UTF-8 text (byte {exc.start}); give a {what} file") from None


def loads_json(text: str, where: str, what: str = "JSON", *, advice: str | None = None):
    """``json.loads`` with one-line errors naming ``where`` and a nesting limit of :data:`MAX_DEPTH`.

    A syntax error reads ``"{where}: not a {what} (not valid JSON: {reason} at line L column C); {advice}"``.
    """
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as exc:
        raise ValueError(f"{where}: not a {what} (not valid JSON: {exc.msg} at line {exc.lineno} column "
                         f"{exc.colno}); {advice or f'give a {what} file'}") from None
    except RecursionError:
        doc = None
        ok = False
    else:
        ok = _depth_ok(doc, MAX_DEPTH)
    if not ok:
        raise ValueError(f"{where}: nested more than {MAX_DEPTH} levels deep; not a {what} file")
    return doc


def read_json(path, what: str = "JSON file", *, advice: str | None = None):
    """Read a JSON file the user gave (size, encoding, syntax and depth checked; one-line errors)."""
    path = Path(path)
    return loads_json(_read_text(path, what), str(path), what, advice=advice)


#: Largest YAML file accepted (bytes): YAML is parsed by Python code (PyYAML), a few MB/s, and the files the
#: program reads as YAML (schema, ship, campaign) are a few kB.
MAX_YAML_BYTES = 4 * 1024 * 1024
#: Most aliases (``*name``) a YAML file may use; anchors and aliases are for a few shared ``defaults``.
MAX_ALIASES = 256
#: Most nodes a YAML document may stand for with every alias expanded (computed without expanding them).
MAX_EXPANDED_NODES = 1_000_000


def _yaml_loader():
    import yaml  # type: ignore  # optional (the yaml extra): only for YAML files

    return getattr(yaml, "CSafeLoader", None) or yaml.SafeLoader


def _yaml_bounds(text: str, where: str, what: str) -> None:
    """Refuse a YAML text whose aliases, nesting or expanded size exceed the limits, from its parse events.

    PyYAML warns that aliases let a small document stand for an exponentially large one ("billion laughs"):
    nine lines of nine aliases each stand for 9**9 nodes.  The events are read once, in order, and each
    anchored node's nesting height and expanded size are recorded when it closes, so an alias costs one
    look-up: the check is linear in the text and never builds the expanded document.
    """
    import yaml  # type: ignore  # optional (the yaml extra): only for YAML files

    stack: list[list] = []  # open collections: [anchor, size, height of the children]
    size: dict = {}
    height: dict = {}
    aliases = 0
    depth_msg = f"{where}: nested more than {MAX_DEPTH} levels deep (aliases counted expanded); not a {what} file"

    def close(anchor, n, h):
        if anchor is not None:
            size[anchor], height[anchor] = n, h
        if stack:
            stack[-1][1] += n
            stack[-1][2] = max(stack[-1][2], h)
            if len(stack) + h > MAX_DEPTH:
                raise ValueError(depth_msg)
        elif n > MAX_EXPANDED_NODES:
            raise ValueError(f"{where}: its aliases expand to {n:.3g} nodes (limit {MAX_EXPANDED_NODES:.0e}); "
                             f"write the {what} without aliases")

    for ev in yaml.parse(text, Loader=_yaml_loader()):
        kind = type(ev).__name__
        if kind in ("SequenceStartEvent", "MappingStartEvent"):
            stack.append([ev.anchor, 1, 0])
            if len(stack) > MAX_DEPTH:
                raise ValueError(depth_msg)
        elif kind in ("SequenceEndEvent", "MappingEndEvent"):
            anchor, n, h = stack.pop()
            close(anchor, n, h + 1)
        elif kind == "ScalarEvent":
            close(ev.anchor, 1, 0)
        elif kind == "AliasEvent":
            aliases += 1
            if aliases > MAX_ALIASES:
                raise ValueError(f"{where}: more than {MAX_ALIASES} YAML aliases (*name); write the {what} "
                                 "with fewer aliases (or as JSON)")
            if ev.anchor not in size:  # an alias to its own enclosing node (a recursive document)
                raise ValueError(f"{where}: YAML alias *{str(ev.anchor)[:30]} refers to a node that contains it; "
                                 f"not a {what} file")
            close(None, size[ev.anchor], height[ev.anchor])
        if stack and stack[0][1] > MAX_EXPANDED_NODES:
            raise ValueError(f"{where}: its aliases expand to more than {MAX_EXPANDED_NODES:.0e} nodes, the limit; "
                             f"write the {what} without aliases")


def loads_yaml(text: str, where: str, what: str = "YAML"):
    """``yaml.safe_load`` after bounds read from the parse events (:func:`_yaml_bounds`): at most
    :data:`MAX_ALIASES` aliases, nesting at most :data:`MAX_DEPTH` and at most :data:`MAX_EXPANDED_NODES`
    nodes with the aliases expanded, each counted without expanding anything; every refusal is one line."""
    import yaml  # type: ignore  # optional (the yaml extra): only for YAML files

    if len(text) > MAX_YAML_BYTES:
        raise ValueError(f"{where}: {len(text) / 2**20:.1f} MiB is too large for a YAML {what} file "
                         f"(limit {MAX_YAML_BYTES // 2**20} MiB)")
    try:
        _yaml_bounds(text, where, what)
        doc = yaml.load(text, Loader=_yaml_loader())  # noqa: S506 - a safe loader
    except yaml.YAMLError as exc:
        if "nesting depth" in str(getattr(exc, "problem", "")):  # libyaml's own limit (1000) is above ours
            raise ValueError(f"{where}: nested more than {MAX_DEPTH} levels deep; not a {what} file") from None
        mark = getattr(exc, "problem_mark", None)
        at = f" at line {mark.line + 1} column {mark.column + 1}" if mark is not None else ""
        raise ValueError(f"{where}: not valid YAML ({getattr(exc, 'problem', None) or 'syntax error'}{at})") from None
    except RecursionError:
        raise ValueError(f"{where}: nested too deeply; not a {what} file") from None
    return doc


def read_structured(path, what: str, *, advice: str | None = None, yaml_ok: bool | None = None):
    """The one reader of the structured files the program is given (schema, ship, result, campaign, problem,
    route, samples, wind): a regular UTF-8 file of at most :data:`MAX_FILE_BYTES` (checked before reading),
    YAML for a ``.yaml``/``.yml`` name (bounded by :func:`loads_yaml`) else JSON (nesting at most
    :data:`MAX_DEPTH`).  ``yaml_ok=False`` refuses YAML.  Every refusal is one line naming the file."""
    path = Path(path)
    is_yaml = path.suffix.lower() in (".yaml", ".yml")
    if is_yaml and yaml_ok is False:
        raise ValueError(f"{path}: a {what} is read as JSON; convert the YAML to JSON")
    if is_yaml:
        if importlib.util.find_spec("yaml") is None:
            raise ValueError(f"{path}: reading YAML needs PyYAML (pip install pyyaml); or write the {what} as JSON")
        _check_size(path, what, MAX_YAML_BYTES)
        return loads_yaml(_read_text(path, what), str(path), what)
    return loads_json(_read_text(path, what), str(path), what, advice=advice)


def _check_size(path: Path, what: str, limit: int) -> None:
    try:
        size = path.stat().st_size
    except OSError:
        return  # _read_text says what is wrong
    if path.is_file() and size > limit:
        raise ValueError(f"{path}: {size / 2**20:.1f} MiB is too large for a {what} (limit {limit / 2**20:g} MiB)")


def memory_limit_bytes() -> float:
    """Memory a single computation may plan to use: half of the physical memory
    (``SHIPID_MEMORY_LIMIT_GB`` overrides it)."""
    env = os.environ.get("SHIPID_MEMORY_LIMIT_GB")
    if env:
        try:
            return float(env) * 2**30
        except ValueError:
            raise ValueError(f"SHIPID_MEMORY_LIMIT_GB={short(env, 20)}: give a number of GiB, e.g. 4") from None
    try:
        return 0.5 * os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):
        return 4.0 * 2**30


def check_memory(nbytes: float, what: str, advice: str) -> None:
    """ValueError ``"{what} needs about X GiB ... {advice}"`` when ``nbytes`` exceeds :func:`memory_limit_bytes`."""
    limit = memory_limit_bytes()
    if nbytes > limit:
        raise ValueError(f"{what} needs about {nbytes / 2**30:.3g} GiB of memory (limit {limit / 2**30:.3g} GiB, "
                         f"half of this machine's; SHIPID_MEMORY_LIMIT_GB sets it); {advice}")


# ----------------------------------------------------------------- schema checks
def check_keys(doc: dict, allowed, where: str) -> None:
    """ValueError naming the first unknown keys of ``doc`` and the allowed ones."""
    unknown = sorted(str(k) for k in set(doc) - set(allowed))
    if unknown:
        shown = ", ".join(short(k, 30) for k in unknown[:3]) + (" ..." if len(unknown) > 3 else "")
        raise ValueError(f"{where}: unknown key(s) {shown}; allowed: {', '.join(sorted(allowed))}")


def as_mapping(value, where: str, example: str = '{"name": value}') -> dict:
    if not isinstance(value, dict):
        raise ValueError(f"{where}: expected an object like {example}, got {type(value).__name__} {short(value, 40)}")
    return value


def as_string(value, where: str) -> str:
    if not isinstance(value, str):
        raise ValueError(f"{where}: expected a string, got {type(value).__name__} {short(value, 40)}")
    return value


def as_bool(value, where: str) -> bool:
    if not isinstance(value, bool):
        raise ValueError(f"{where}: expected true or false, got {short(value, 40)}")
    return value


def as_number(value, where: str, *, low: float | None = None, high: float | None = None,
              low_open: bool = False, allow_none: bool = False, finite: bool = True):
    """A JSON number as float (``true``/``false`` and strings refused); optional range check."""
    if value is None and allow_none:
        return None
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise ValueError(f"{where}: expected a number, got {type(value).__name__} {short(value, 40)}")
    try:
        v = float(value)
    except OverflowError:
        raise ValueError(f"{where}: a {len(str(value))}-digit number is too large") from None
    if finite and not math.isfinite(v):
        raise ValueError(f"{where}: expected a finite number, got {v}")
    if low is not None and (v < low or (low_open and v == low)):
        raise ValueError(f"{where}: must be {'>' if low_open else '>='} {low:g}, got {v:g}")
    if high is not None and v > high:
        raise ValueError(f"{where}: must be <= {high:g}, got {v:g}")
    return v


def as_int(value, where: str, *, low: int | None = None, high: int | None = None) -> int:
    """A JSON integer (``3.0`` accepted, ``3.5``/``true``/``"3"`` refused) with an optional range."""
    v = as_number(value, where)
    if v != int(v):
        raise ValueError(f"{where}: expected a whole number, got {v:g}")
    v = int(v)
    shown = f"{v}" if abs(v) < 10**12 else f"{v:.3g}"  # never echo a 300-digit number
    if low is not None and v < low:
        raise ValueError(f"{where}: must be >= {low}, got {shown}")
    if high is not None and v > high:
        raise ValueError(f"{where}: must be <= {high}, got {shown}")
    return v


def sha256_file(path: str | os.PathLike) -> str:
    """Hex SHA-256 of a file's bytes."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()
