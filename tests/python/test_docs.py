"""Docs that resolve (issue 45 [3]): every `.md` file the code, the benchmarks and the tools
cite exists in the repository, and a section cited by its heading (a doc's name, a comma and
the heading in double quotes) is there. Before: src/scene/camera.rs, src/scene/light.rs and
benchmarks/gdmlt_bench/peers.py cited a design note that is not in the repository, and
peers.py another."""

import re

from conftest import ROOT

SOURCES = [p for d in ("src", "python", "benchmarks", "blender_addon", "tools", "tests")
           for p in (ROOT / d).rglob("*") if p.suffix in (".rs", ".py") and ".venv" not in p.parts and p.name != "test_docs.py"]
CITATION = re.compile(r"\b((?:docs/)?[\w-]+\.md)(?:,? \"([^\"]+)\")?")


def _headings(path):
    return {line.lstrip("#").strip() for line in path.read_text().splitlines() if line.startswith("#")}


def test_every_cited_doc_and_section_exists():
    missing = []
    for src in SOURCES:
        for n, line in enumerate(src.read_text(errors="replace").splitlines(), 1):
            for name, section in CITATION.findall(line):
                doc = ROOT / name if name.startswith("docs/") or (ROOT / name).exists() else ROOT / "docs" / name
                where = f"{src.relative_to(ROOT)}:{n}"
                if not doc.exists():
                    missing.append(f"{where}: {name}")
                elif section and section not in _headings(doc):
                    missing.append(f"{where}: {name} has no section '{section}'")
    assert not missing, "\n".join(missing)
