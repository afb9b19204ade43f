"""The editor's list of a file's joints (``service/static/editor/bvhnames.js``, the joint-map
template's) is the service's reader's (``core.bvh``), name for name, on real files and on
them as other tools write them (run in Node). Was: each JOINT line's text, trimmed, so that
``JOINT Neck {`` was listed as ``Neck {``, and the service called a file's ``Left  Hand``
``Left Hand``: a name copied from the list was refused (an audit, 2026-12-06)."""

from __future__ import annotations

import json
import re
import shutil
import subprocess
from pathlib import Path

import pytest

from core.bvh import parse_bvh
from tests.conftest import REPO_ROOT
from tests.core.test_bvh_names import odd_names

NAMES_JS = REPO_ROOT / "service" / "static" / "editor" / "bvhnames.js"
#: reads JSON [text, ...] on stdin, writes [[name, ...], ...]
RUN = """
const { fileJoints } = await import(process.argv[1]);
let input = '';
for await (const chunk of process.stdin) input += chunk;
console.log(JSON.stringify(JSON.parse(input).map(fileJoints)));
"""


def _editor_names(texts: list[str]) -> list[list[str]]:
    node = shutil.which("node")
    if node is None:
        pytest.skip("node is needed to run the editor's module")
    done = subprocess.run(
        [node, "--input-type=module", "-e", RUN, NAMES_JS.as_uri()],
        input=json.dumps(texts),
        capture_output=True,
        text=True,
        timeout=60,
        check=True,
    )
    out: list[list[str]] = json.loads(done.stdout)
    return out


def _variants(text: str) -> dict[str, str]:
    """``text`` as other tools write it."""
    crlf = text.replace("\n", "\r\n")
    one_line = re.sub(r"\n\s*\{", " {", text)  # every '{' on its joint's (or End Site's) line
    hand_end = text.replace("JOINT LeftHandThumb1\n", "JOINT LeftHandEnd_end\n")
    return {
        "as-is": text,
        "odd-names": odd_names(text),
        "odd-names-crlf-bom": "\ufeff" + odd_names(text).replace("\n", "\r\n"),
        "crlf": crlf,
        "cr": text.replace("\n", "\r"),
        "braces-on-the-line": one_line,
        "a-joint-named-as-an-end-site": hand_end,  # its End Site is then LeftHandEnd_end2
    }


def test_the_editor_lists_the_names_the_service_reads(bvh_files: dict[str, Path]) -> None:
    texts: dict[str, str] = {}
    for name, path in bvh_files.items():
        texts[name] = path.read_text()
    for name, text in _variants(texts["fair1-child-inches-zup"]).items():
        texts[f"fair1-{name}"] = text
    want = {name: [j.name for j in parse_bvh(t, name).joints] for name, t in texts.items()}
    got = dict(zip(texts, _editor_names(list(texts.values())), strict=True))
    for name in texts:
        assert got[name] == want[name], name
    odd = got["fair1-odd-names-crlf-bom"]
    assert "Left  Hand" in odd and "Right\tHand" in odd and "Neck" in odd
    assert "LeftHandEnd_end2" in got["fair1-a-joint-named-as-an-end-site"]
