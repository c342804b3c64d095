"""Uploaded scenes checked so that nothing outside an upload is ever read (untrusted input).

In this order, before any stage is composed for rendering:

1. ``check_usdz`` (plain ``zipfile``, no pxr): every entry name stays inside the package (no absolute names, no
   ``..``, no backslashes or drive letters), entries are stored uncompressed as USDZ requires (so no zip bombs),
   their count and total size are bounded, and the first entry is a USD layer.
2. ``check_asset_paths`` (pxr, in an inspection process): every layer of the upload is parsed alone (``Sdf`` layer, no
   composition) and every asset path it names (sublayers, references, payloads, variants, clips, and
   asset-valued attributes such as textures) must resolve to a file of the upload: a ``.usdz``'s own entries, or
   the single uploaded file itself (a UDIM pattern needs at least one of its tiles). Absolute paths, URLs, ``..``
   escapes, package-relative (``a.usdz[b]``) and expression paths, and missing files are rejected naming the path.
   Layers found this way are checked in turn.

Only then does ``load_scene`` open the stage, and every asset it can reach is inside the upload.
"""
from __future__ import annotations

import os
import posixpath
import re
import zipfile
from pathlib import Path

from ..queue.scenes import UploadError

SCENE_EXTENSIONS = (".usda", ".usdc", ".usd", ".usdz")
LAYER_EXTENSIONS = (".usda", ".usdc", ".usd")


def scene_extension(filename: str | None) -> str:
    ext = os.path.splitext(filename or "")[1].lower()
    if ext not in SCENE_EXTENSIONS:
        raise UploadError("scene must be a .usda, .usdc, .usd or .usdz file")
    return ext


def safe_name(filename: str, ext: str) -> str:
    """The upload's own base name when it is plain (messages then name the user's file), else ``scene<ext>``."""
    base = os.path.basename(filename.replace("\\", "/"))
    stem = base[: -len(ext)] if base.lower().endswith(ext) else ""
    if re.fullmatch(r"[A-Za-z0-9][A-Za-z0-9._-]{0,99}", stem or "-") is None:
        stem = "scene"
    return stem + ext


# -------------------------------------------------------------------------------------------------------------
# .usdz packages


def _entry_escapes(name: str) -> bool:
    if not name or name.startswith("/") or "\\" in name or re.match(r"^[A-Za-z]:", name):
        return True
    return any(part == ".." for part in name.split("/"))


def check_usdz(path: Path, max_unpacked: int, max_entries: int) -> None:
    try:
        with zipfile.ZipFile(path) as zf:
            infos = zf.infolist()
    except (zipfile.BadZipFile, OSError, ValueError):
        raise UploadError(".usdz is not a valid zip archive") from None
    if not infos:
        raise UploadError(".usdz package is empty")
    if len(infos) > max_entries:
        raise UploadError(f".usdz has more than {max_entries} entries")
    total = 0
    for info in infos:
        name = info.filename
        if _entry_escapes(name):
            raise UploadError(f".usdz entry escapes the package: {name}")
        if info.flag_bits & 0x1:
            raise UploadError(f".usdz entry is encrypted: {name}")
        if info.compress_type != zipfile.ZIP_STORED:
            raise UploadError(f".usdz entry is compressed (USDZ stores entries uncompressed): {name}")
        total += info.file_size
    if total > max_unpacked:
        raise UploadError(f".usdz unpacks to more than {max_unpacked} bytes")
    if os.path.splitext(infos[0].filename)[1].lower() not in LAYER_EXTENSIONS:
        raise UploadError(f".usdz must start with a USD layer, found {infos[0].filename}")


# -------------------------------------------------------------------------------------------------------------
# Asset paths (pxr: runs in an inspection process, like everything of ours that parses an upload)


def _resolve_inside(anchor_entry: str, asset: str) -> str:
    """The upload-relative name ``asset`` (authored in ``anchor_entry``) points at; UploadError if it leaves."""
    if "`" in asset:
        raise UploadError(f"asset path expressions are not supported: {asset}")
    if re.match(r"^[A-Za-z][A-Za-z0-9+.-]+:", asset):
        raise UploadError(f"asset path is a URL: {asset}")
    if asset.startswith(("/", "\\")) or re.match(r"^[A-Za-z]:", asset):
        raise UploadError(f"asset path is absolute: {asset}")
    if "[" in asset or "]" in asset:
        raise UploadError(f"package-relative asset paths are not supported: {asset}")
    rel = posixpath.normpath(posixpath.join(posixpath.dirname(anchor_entry), asset.replace("\\", "/")))
    if rel == ".." or rel.startswith("../") or rel.startswith("/"):
        raise UploadError(f"asset path escapes the upload: {asset}")
    return rel


def hide_dir(text: str, directory: Path) -> str:
    """A message without the server's directory (clients see their own file names only)."""
    return text.replace(str(directory) + os.sep, "").replace(str(directory), ".")


def _present(target: str, entries: set[str]) -> bool:
    """``target`` is a file of the upload; a UDIM pattern (``wood.<UDIM>.png``) needs one tile of it."""
    if "<UDIM>" not in target:
        return target in entries
    pattern = re.compile(re.escape(target).replace(re.escape("<UDIM>"), r"1\d{3}") + r"\Z")
    return any(pattern.match(e) for e in entries)


def _parse_failure(name: str, err: Exception, directory: Path) -> UploadError:
    from renderer.usd.stage import malformed_usd_message

    return UploadError(malformed_usd_message(name, Exception(hide_dir(str(err), directory))))


def check_asset_paths(path: Path) -> None:
    """Every asset path reachable from the upload at ``path`` resolves inside it (see the module docstring)."""
    from pxr import UsdUtils

    path = Path(path)
    if path.suffix.lower() == ".usdz":
        with zipfile.ZipFile(path) as zf:
            names = zf.namelist()
        entries = set(names)
        root = names[0]

        def identifier(entry: str) -> str:
            return f"{path}[{entry}]"

        display = lambda entry: f"{path.name}[{entry}]"  # noqa: E731
    else:
        root = path.name
        entries = {root}

        def identifier(entry: str) -> str:
            return str(path)

        display = lambda entry: entry  # noqa: E731

    seen = {root}
    todo = [root]
    while todo:
        entry = todo.pop()
        try:
            sublayers, references, payloads = UsdUtils.ExtractExternalReferences(identifier(entry))
        except Exception as e:  # noqa: BLE001 - pxr raises Tf.ErrorException (and others) for unreadable layers
            raise _parse_failure(display(entry), e, path.parent) from None
        for asset in [*sublayers, *references, *payloads]:
            if not asset:
                continue
            target = _resolve_inside(entry, asset)
            if not _present(target, entries):
                raise UploadError(f"asset not found in the upload: {asset}")
            if os.path.splitext(target)[1].lower() == ".usdz":
                raise UploadError(f"nested .usdz packages are not supported: {asset}")
            if os.path.splitext(target)[1].lower() in LAYER_EXTENSIONS and target not in seen:
                seen.add(target)
                todo.append(target)
