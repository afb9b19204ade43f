"""Where each map's data is found (``trainer.data.sources``): a folder source's hash, its
linked folders, an archive beside its extracted folder."""

from __future__ import annotations

import json
import shutil
from pathlib import Path
from typing import Any

from trainer.data.dataset import load_dataset


def test_a_folder_source_is_hashed_as_sha256sum_lists_its_files(tmp_path: Path) -> None:
    import hashlib

    from trainer.data.sources import folder_digest

    (tmp_path / "b").mkdir()
    (tmp_path / "a.bvh").write_bytes(b"one")
    (tmp_path / "b" / "c.bvh").write_bytes(b"two")
    listing = "".join(
        f"{hashlib.sha256(data).hexdigest()}  {rel}\n"
        for rel, data in (("a.bvh", b"one"), ("b/c.bvh", b"two"))
    )
    want = hashlib.sha256(listing.encode()).hexdigest()
    assert folder_digest(tmp_path, ["b/c.bvh", "a.bvh"]) == want  # sorted by path
    (tmp_path / "a.bvh").write_bytes(b"changed")
    assert folder_digest(tmp_path, ["a.bvh", "b/c.bvh"]) != want


def test_symlinked_folders_of_a_folder_source_are_read_once(
    small_dataset: Path, mocap_clips: Any, tmp_path: Path
) -> None:
    """A studio audit (D1): a source folder assembled from links (an actor's folder linked
    from a NAS) had its linked folders silently not read (a linked *file* was read): the
    clips under them were missing from the dataset, unsaid. Linked folders are now read; a
    link to a folder inside the source (read as itself) or back to an ancestor is not read
    twice, nor walked forever."""
    from trainer.data.build import build_dataset

    root = tmp_path / "mocap"
    shutil.copytree(mocap_clips.root, root)
    nas = tmp_path / "nas"
    nas.mkdir()
    data = root / "dataset" / "Bandai-Namco-Research-Motiondataset-2"
    data.rename(nas / "bn2")
    data.symlink_to(nas / "bn2", target_is_directory=True)
    (root / "train_data_bvh" / "again").symlink_to(root / "train_data_bvh" / "salsa")
    (root / "dataset" / "loop").symlink_to(root, target_is_directory=True)
    out = tmp_path / "linked.npz"
    build_dataset(root, out, seed=0, workers=2, progress=False)
    linked, direct = load_dataset(out), load_dataset(small_dataset)
    assert sorted(linked.clip_name.tolist()) == sorted(direct.clip_name.tolist())
    assert len(linked.positions) == len(direct.positions)


def test_an_archive_beside_its_extracted_folder_is_read_and_the_folder_named(
    mocap_clips: Any, tmp_path: Path
) -> None:
    """A studio audit (D10): with an archive and its extracted folder (more takes added
    since) both in ``--mocap``, the archive was read and the folder silently not. The
    archive is still read; a warning names both, the folder's file count, and which was
    read."""
    import subprocess

    from trainer.data.build import build_dataset

    mocap = tmp_path / "mocap"
    folder = mocap / "bandai-namco-research-motiondataset"
    shutil.copytree(mocap_clips.root / "dataset", folder / "dataset")
    archive = mocap / "bandai-namco-research-motiondataset.tar.xz"
    subprocess.run(
        ["tar", "-cJf", str(archive), "-C", str(folder),
         "dataset/Bandai-Namco-Research-Motiondataset-1"],
        check=True,
    )  # fmt: skip
    out = tmp_path / "both.npz"
    build_dataset(mocap, out, seed=0, workers=2, progress=False)
    data = load_dataset(out)
    assert {str(n).split("/")[1].split("_")[0] for n in data.clip_name} == {"dataset-1"}
    files = len(list(folder.rglob("*.bvh")))
    want = (
        f"both the archive {archive} and the extracted folder {folder}/ ({files} files the map "
        f"selects) are in {mocap}: the archive was read, the folder not"
    )
    assert any(want in w for w in data.meta["warnings"]), data.meta["warnings"]


def test_an_archive_in_a_folder_without_sha256sums_says_so(
    mocap_clips: Any, tmp_path: Path
) -> None:
    """A studio audit (2026-12-07): a mocap folder with no SHA256SUMS at all said
    ``X.tar.xz: not listed in SHA256SUMS, checksum not verified``, of a file that is not
    there (and the model card likewise). It now says there is none; with a SHA256SUMS that
    does not list the archive, as before. The origin, the manifest's entry and the card
    line say which."""
    import subprocess

    from trainer.data.build import build_dataset
    from trainer.export import recorded_source
    from trainer.model_card import _archive_line

    mocap = tmp_path / "mocap"
    mocap.mkdir()
    archive = mocap / "bandai-namco-research-motiondataset.tar.xz"
    subprocess.run(
        ["tar", "-cJf", str(archive), "-C", str(mocap_clips.root),
         "dataset/Bandai-Namco-Research-Motiondataset-1"],
        check=True,
    )  # fmt: skip
    for sums, said, card in (
        (None, f"no SHA256SUMS in {mocap}: checksum of {archive.name} not verified",
         "(no SHA256SUMS beside it: not verified)"),
        ("0" * 64 + "  other.tar.xz\n",
         f"{archive.name}: not listed in SHA256SUMS, checksum not verified",
         "(not listed in SHA256SUMS: not verified)"),
    ):  # fmt: skip
        if sums is not None:
            (mocap / "SHA256SUMS").write_text(sums)
        lines: list[str] = []
        report = build_dataset(
            mocap, tmp_path / "d.npz", seed=0, workers=1, progress=False, log=lines.append
        )
        assert any(said in line for line in lines), lines
        assert not any("not listed" in line for line in lines) or sums is not None, lines
        (origin,) = [a for a in report.meta["archives"] if a["file"] == archive.name]
        entry = recorded_source(origin)
        assert entry["verified"] == "false"
        assert (entry.get("sha256sums") == "absent") is (sums is None), entry
        assert _archive_line(entry).endswith(card), _archive_line(entry)


def test_a_map_is_recorded_by_its_name_not_a_local_path(mocap_clips: Any, tmp_path: Path) -> None:
    """A studio audit (2026-12-07): ``meta["maps"][].file`` (the models'
    ``provenance.dataset.maps``) kept a map's absolute local path, though sources are named
    by name. A map of one's own is now named by its file name, with its sha256; a shipped
    one by its place in the repository."""
    import hashlib

    from trainer.data.build import build_dataset

    shipped = Path(__file__).resolve().parents[2] / "trainer" / "maps" / "bandai_namco.toml"
    maps = tmp_path / "my maps"
    maps.mkdir()
    shutil.copy(shipped, maps / "studio_bandai.toml")
    mocap = tmp_path / "mocap"
    shutil.copytree(mocap_clips.root / "dataset", mocap / "dataset")
    want = hashlib.sha256(shipped.read_bytes()).hexdigest()
    for folder, name in ((maps, "studio_bandai.toml"), (None, "trainer/maps/bandai_namco.toml")):
        report = build_dataset(
            mocap, tmp_path / "d.npz", maps_dir=folder, workers=1, progress=False
        )
        (entry,) = [m for m in report.meta["maps"] if m["source"] == "bandai-namco"]
        assert entry == {"source": "bandai-namco", "file": name, "sha256": want}, entry
        assert str(tmp_path) not in json.dumps(report.meta["maps"])
