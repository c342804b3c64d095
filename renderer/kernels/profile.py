"""Sample-based profile-guided optimisation of the render kernels: the profile clang reads when it compiles one.

``renderer/kernels/profiles/<module>.prof`` is an LLVM sample profile (text format) of a module's kernel: how often each
line of its generated C++ ran, per inline call site, measured with ``perf`` on the bench scenes by
``bench/sample_profile.py``. Given it (``-fprofile-sample-use``), clang lays the hot paths out straight and keeps
cold code out of their way; the integrator renders 1-12 % faster with the same pixels (the profile changes where
code goes, never what it computes).

A profile names functions as Warp generates them, with hashes: the kernel's (``trace_wave_kernel_9ce3eecc``)
changes with any change to its code, the structs' with their fields. Before each compile the stored profile is
written out with today's hashes (``write_profile``), so a profile taken before a change still guides the
functions the change left alone: line numbers count from each function's first line.

The flags name the profile by its file name and the stored profile's digest. They are part of Warp's cache key,
so the portable build (``kernel_cache``) names it without a directory: its key is then the same on every
machine, and only ``drt warmup --prebuilt`` reads the file (in a directory of its own, ``compiling_in``).
"""
from __future__ import annotations

import contextlib
import functools
import hashlib
import os
import pathlib
import re
import tempfile

from renderer.core.files import atomic_write

PROFILES = pathlib.Path(__file__).parent / "profiles"
# -debug-info-kind=line-directives-only: the debug locations a sample profile is matched by, without DWARF in the
# object (the code is the same as with line tables; the object a quarter of the size); -no-integrated-as: no
# .llvm.call-graph-profile section, whose SHT_REL relocations Warp's JIT linker refuses;
# -profile-guided-section-prefix=false: the hot kernel stays in the object's one code section (.ltext), which
# bench/kernel_profile.py maps samples by (one JIT-loaded object gains nothing from grouping hot functions)
PGO_FLAGS = ("-debug-info-kind=line-directives-only -no-integrated-as -mllvm=-profile-guided-section-prefix=false"
             " -fprofile-sample-use={}")


def stored_profile(module_name: str) -> pathlib.Path | None:
    path = PROFILES / f"{module_name}.prof"
    return path if path.is_file() else None


@functools.lru_cache(maxsize=None)
def _file_name(module_name: str, digest_of: pathlib.Path) -> str:
    return f"{module_name}-{hashlib.sha256(digest_of.read_bytes()).hexdigest()[:8]}.prof"


def profile_flags(mod, directory: pathlib.Path | None = None) -> str:
    """Clang flags that compile Warp module ``mod`` with its stored sample profile, read from ``directory`` (None:
    the working directory); "" when it has none."""
    stored = stored_profile(mod.name)
    if stored is None:
        return ""
    name = _file_name(mod.name, stored)
    return PGO_FLAGS.format(name if directory is None else directory / name)


def current_names(mod) -> dict[str, str]:
    """Warp's hashed native names of ``mod``'s kernels and of every struct Warp knows, by their plain names
    (a struct name two modules share is left out: its hash cannot be told from the name)."""
    from warp._src.context import user_modules

    names, shared = {}, set()
    for m in list(user_modules.values()):
        for key, struct in m.structs.items():
            if names.get(key, struct.native_name) != struct.native_name:
                shared.add(key)
            names[key] = struct.native_name
    for key in shared:
        del names[key]
    mod.get_module_identifier()  # hashes the kernels
    for k in mod.kernels.values():
        names[k.key] = k.get_mangled_name()
        names[f"wp_args_{k.key}"] = f"wp_args_{k.get_mangled_name()}"  # its arguments' struct
    return names


def renew_names(text: str, names: dict[str, str]) -> str:
    """``text`` with every hashed name ``<plain>_<8 hex digits>`` of ``names`` given today's hash. A name inside
    a mangled one follows its length digits, so only a letter or an underscore before it makes it another name."""
    if not names:
        return text
    pattern = re.compile(r"(?<![A-Za-z_])(" + "|".join(map(re.escape, sorted(names, key=len, reverse=True)))
                         + r")_[0-9a-f]{8}")
    return pattern.sub(lambda m: names[m.group(1)], text)


def write_profile(mod, directory: pathlib.Path) -> pathlib.Path | None:
    """Write ``mod``'s stored profile into ``directory`` under the name ``profile_flags`` gives it, with today's
    hashes (atomically: another process may be compiling from it); None when it has none."""
    stored = stored_profile(mod.name)
    if stored is None:
        return None
    directory.mkdir(parents=True, exist_ok=True)
    path = directory / _file_name(mod.name, stored)
    with atomic_write(path, "w", durable=False) as f:  # read by a compile now, not needed after a crash
        f.write(renew_names(stored.read_text(), current_names(mod)))
    return path


@contextlib.contextmanager
def compiling_in(mods):
    """Run the block (a compile of the portable build) in a scratch working directory holding the profiles of
    ``mods``, as flags without a directory name them."""
    saved = os.getcwd()
    with tempfile.TemporaryDirectory(prefix="drt-profiles-") as scratch:
        for mod in mods:
            write_profile(mod, pathlib.Path(scratch))
        os.chdir(scratch)
        try:
            yield
        finally:
            os.chdir(saved)
