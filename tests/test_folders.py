"""The frame and scan folder format (lts360.folders)."""

import json

import pytest

from lts360 import folders


def test_frame_and_scan_folders(tmp_path):
    frame = tmp_path / "f"
    frame.mkdir()
    folders.write_json_atomic(folders.frame_file(frame), {"stage": {"z_mm": 1.5}})
    assert folders.is_frame(frame) and not folders.is_scan(frame)
    assert folders.frame_dirs(frame) == [frame]
    assert folders.first_frame_meta(frame)["stage"]["z_mm"] == 1.5
    scan = tmp_path / "s"
    for k in range(2):
        d = scan / folders.section_dir_name(k)
        d.mkdir(parents=True)
        folders.write_json_atomic(folders.frame_file(d), {"stage": {"z_mm": float(k)}})
    folders.write_scan_meta(scan, {"sections": [{"dir": folders.section_dir_name(k), "z_mm": k}
                                                for k in range(2)]})
    assert folders.is_scan(scan)
    assert [m["stage"]["z_mm"] for m in folders.frame_metas(scan)] == [0.0, 1.0]
    assert folders.first_frame_meta(scan)["stage"]["z_mm"] == 0.0
    assert not list(scan.glob(".*.tmp"))  # the atomic writer left nothing behind


def test_neither_frame_nor_scan_and_a_broken_scan_are_named(tmp_path):
    with pytest.raises(ValueError, match="--truth: .* holds neither frame.json nor scan.json"):
        folders.frame_dirs(tmp_path)
    (tmp_path / folders.SCAN_FILE).write_text(json.dumps({"object": "x"}))
    with pytest.raises(ValueError, match="no list of 'sections'"):
        folders.section_dirs(tmp_path)


def test_no_other_module_spells_the_file_names():
    """One module owns the format: no other source file writes the names as string literals."""
    from pathlib import Path

    import lts360

    src = Path(lts360.__file__).parent
    offenders = []
    for p in src.rglob("*.py"):
        if p.name == "folders.py":
            continue
        text = p.read_text()
        for name in ('"frame.json"', '"scan.json"', '"image.png"', "'frame.json'", "'scan.json'"):
            if name in text:
                offenders.append(f"{p.relative_to(src)}: {name}")
    assert offenders == []
