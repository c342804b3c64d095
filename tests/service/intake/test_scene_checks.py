"""Untrusted uploads: asset paths must resolve inside the upload, .usdz entries are checked, nothing outside is read."""
from __future__ import annotations

import io
import os
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

from service.intake.scene_checks import check_asset_paths, check_usdz, safe_name, scene_extension
from service.queue.scenes import SceneStore, UploadError, UploadTooLarge

from service_helpers import cli_env, write_card

LAYER = '#usda 1.0\n{meta}\ndef Xform "World" ({prim})\n{{\n{body}}}\n'


def layer(meta: str = "", prim: str = "", body: str = "") -> str:
    return LAYER.format(meta=f"(\n    {meta}\n)" if meta else "", prim=f"\n    {prim}\n" if prim else "", body=body)


def write(path: Path, text: str) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)
    return path


@pytest.mark.parametrize("text, detail", [
    (layer(prim="references = @/etc/hosts@"), "asset path is absolute: /etc/hosts"),
    (layer(prim="references = @../outside.usda@"), "asset path escapes the upload: ../outside.usda"),
    (layer(prim="payload = @sub/../../outside.usda@"), "asset path escapes the upload: sub/../../outside.usda"),
    (layer(meta="subLayers = [@https://example.com/x.usda@]"), "asset path is a URL: https://example.com/x.usda"),
    (layer(prim="references = @./other.usda@"), "asset not found in the upload: ./other.usda"),
    (layer(body='    def Shader "T"\n    {\n        asset inputs:file = @tex/wood.png@\n    }\n'),
     "asset not found in the upload: tex/wood.png"),
    (layer(body='    def Shader "T"\n    {\n        asset inputs:file.timeSamples = {\n'
                '            1: @/tmp/x.png@,\n        }\n    }\n'),
     "asset path is absolute: /tmp/x.png"),
    (layer(prim='variantSets = "v"\n    variants = { string v = "a" }',
           body='    variantSet "v" = {\n        "a" (references = @../v.usda@) {\n        }\n    }\n'),
     "asset path escapes the upload: ../v.usda"),
    (layer(prim="references = @pkg.usdz[x.usda]@"), "package-relative asset paths are not supported: pkg.usdz[x.usda]"),
])
def test_asset_paths_must_stay_inside_a_single_file_upload(tmp_path, text, detail):
    path = write(tmp_path / "up" / "scene.usda", text)
    with pytest.raises(UploadError) as e:
        check_asset_paths(path)
    assert str(e.value) == detail and e.value.status == 422


def test_a_clean_file_passes_and_may_reference_itself(tmp_path):
    check_asset_paths(write_card(tmp_path / "card.usda"))
    check_asset_paths(write(tmp_path / "self.usda", layer(prim="references = @./self.usda@</World/X>")))


def test_malformed_layer_names_the_line(tmp_path):
    path = write(tmp_path / "bad.usda", '#usda 1.0\ndef Xform "World"\n{\n    int x = [1,\n    what\n}\n')
    with pytest.raises(UploadError) as e:
        check_asset_paths(path)
    assert str(e.value) == ("malformed USD in bad.usda: syntax error at line 6 (column 1): "
                            "parse error matching ListValueClose at '}' in </World.x>")  # as `drt render` says


def test_nothing_outside_the_upload_is_read(tmp_path):
    """The reference points at a FIFO: any attempt to open it would block; the check must answer at once."""
    os.mkfifo(tmp_path / "trap.usda")
    path = write(tmp_path / "up" / "scene.usda",
                 layer(meta="subLayers = [@../trap.usda@]", prim="references = @../trap.usda@"))
    code = ("import sys; from pathlib import Path\n"
            "from service.intake.scene_checks import check_asset_paths\nfrom service.queue.scenes import UploadError\n"
            "try:\n    check_asset_paths(Path(sys.argv[1]))\nexcept UploadError as e:\n    print(e)\n")
    r = subprocess.run([sys.executable, "-c", code, str(path)], capture_output=True, text=True, timeout=60,
                       env=cli_env())
    assert r.stdout.strip() == "asset path escapes the upload: ../trap.usda", r.stderr


# -- .usdz -------------------------------------------------------------------------------------------------------


def usdz(path: Path, entries: dict[str, bytes | str], compress: int = zipfile.ZIP_STORED) -> Path:
    with zipfile.ZipFile(path, "w", compression=compress) as z:
        for name, data in entries.items():
            info = zipfile.ZipInfo(name)  # names exactly as given (ZipFile.write would clean them up)
            info.compress_type = compress
            z.writestr(info, data.encode() if isinstance(data, str) else data)
    return path


def test_a_usdz_may_reference_its_own_entries(tmp_path):
    from pxr import Sdf

    card = write_card(tmp_path / "src" / "card.usda")
    root = write(tmp_path / "src" / "root.usda",
                 layer(meta="subLayers = [@parts/card.usda@]",
                       body='    def Shader "T"\n    {\n        asset inputs:file = @tex/a.png@\n    }\n'))
    (tmp_path / "src" / "parts").mkdir()
    os.replace(card, tmp_path / "src" / "parts" / "card.usda")
    write(tmp_path / "src" / "tex" / "a.png", "not really a png")
    w = Sdf.ZipFileWriter.CreateNew(str(tmp_path / "ok.usdz"))  # pxr's own writer: aligned, stored entries
    for name in ("root.usda", "parts/card.usda", "tex/a.png"):
        w.AddFile(str(tmp_path / "src" / name), name)
    w.Save()
    check_usdz(tmp_path / "ok.usdz", 1 << 20, 100)
    check_asset_paths(tmp_path / "ok.usdz")
    del root


def test_udim_textures_need_a_tile_inside_the_package(tmp_path):
    shader = '    def Shader "T"\n    {{\n        asset inputs:file = @{}@\n    }}\n'
    root = layer(body=shader.format("tex/wood.<UDIM>.png"))
    check_asset_paths(usdz(tmp_path / "ok.usdz", {"root.usda": root, "tex/wood.1001.png": "x"}))
    with pytest.raises(UploadError) as e:
        check_asset_paths(usdz(tmp_path / "no.usdz", {"root.usda": root, "tex/wood.png": "x"}))
    assert str(e.value) == "asset not found in the upload: tex/wood.<UDIM>.png"
    with pytest.raises(UploadError) as e:
        check_asset_paths(usdz(tmp_path / "up.usdz", {"root.usda": layer(body=shader.format("../w.<UDIM>.png"))}))
    assert str(e.value) == "asset path escapes the upload: ../w.<UDIM>.png"


def test_usdz_inner_layer_cannot_escape_the_package(tmp_path):
    pkg = usdz(tmp_path / "p.usdz", {"root.usda": layer(prim="references = @sub/m.usda@"),
                                       "sub/m.usda": layer(prim="references = @../../escape.usda@")})
    check_usdz(pkg, 1 << 20, 100)
    with pytest.raises(UploadError) as e:
        check_asset_paths(pkg)
    assert str(e.value) == "asset path escapes the upload: ../../escape.usda"


@pytest.mark.parametrize("entries, compress, detail", [
    ({"../evil.usda": "#usda 1.0\n"}, zipfile.ZIP_STORED, ".usdz entry escapes the package: ../evil.usda"),
    ({"/abs.usda": "#usda 1.0\n"}, zipfile.ZIP_STORED, ".usdz entry escapes the package: /abs.usda"),
    ({"a\\..\\..\\b.usda": "#usda 1.0\n"}, zipfile.ZIP_STORED, ".usdz entry escapes the package: a\\..\\..\\b.usda"),
    ({"root.usda": "#usda 1.0\n" + " " * 5000}, zipfile.ZIP_DEFLATED,
     ".usdz entry is compressed (USDZ stores entries uncompressed): root.usda"),
    ({"tex.png": "x", "root.usda": "#usda 1.0\n"}, zipfile.ZIP_STORED,
     ".usdz must start with a USD layer, found tex.png"),
    ({"root.usda": "#usda 1.0\n", "big.bin": "x" * 2000}, zipfile.ZIP_STORED, ".usdz unpacks to more than 1000 bytes"),
    ({f"{i}.usda": "" for i in range(5)}, zipfile.ZIP_STORED, ".usdz has more than 4 entries"),
    ({}, zipfile.ZIP_STORED, ".usdz package is empty"),
])
def test_usdz_entries_are_checked(tmp_path, entries, compress, detail):
    pkg = usdz(tmp_path / "p.usdz", entries, compress)
    with pytest.raises(UploadError) as e:
        check_usdz(pkg, 1000, 4)
    assert str(e.value) == detail


def test_not_a_zip(tmp_path):
    (tmp_path / "x.usdz").write_bytes(b"#usda 1.0\n")
    with pytest.raises(UploadError) as e:
        check_usdz(tmp_path / "x.usdz", 1000, 4)
    assert str(e.value) == ".usdz is not a valid zip archive"


# -- storage -----------------------------------------------------------------------------------------------------


def test_names_and_extensions():
    assert scene_extension("shot.USDA") == ".usda"
    with pytest.raises(UploadError) as e:
        scene_extension("shot.abc")
    assert str(e.value) == "scene must be a .usda, .usdc, .usd or .usdz file"
    assert safe_name("shot_01.usda", ".usda") == "shot_01.usda"
    assert safe_name("../../etc/x y.usda", ".usda") == "scene.usda"
    assert safe_name("C:\\tmp\\shot.usdz", ".usdz") == "shot.usdz"


def test_store_is_content_addressed_with_a_size_limit(tmp_path):
    store = SceneStore(tmp_path / "scenes", max_bytes=10)
    tmp, sha, size = store.receive(io.BytesIO(b"0123456789"))
    with store.pinned(tmp, sha, "a.usda", size) as stored:
        assert stored.path.read_bytes() == b"0123456789" and stored.path.parent.name == sha
        assert not store.collect(sha, lambda _: False)  # pinned by the request
    assert store.collect(sha, lambda _: False)
    assert not (tmp_path / "scenes" / sha).exists()
    with pytest.raises(UploadTooLarge) as e:
        store.receive(io.BytesIO(b"0123456789X"))
    assert e.value.status == 413 and str(e.value) == "upload exceeds the limit of 10 bytes"
    assert list((tmp_path / "scenes" / ".incoming").iterdir()) == []
