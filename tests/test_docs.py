"""The documents a new user reads: a short README that starts with the set-up, pictures that exist, docs by purpose."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
DOCS = ("guide.md", "formats.md", "plugins.md", "design.md", "benchmarks.md")


def test_readme_is_short_and_starts_with_the_two_set_up_commands():
    lines = README.read_text().splitlines()
    assert len(lines) <= 300
    first_block = lines[lines.index("```bash") + 1: lines.index("```")]
    assert first_block[0].startswith("make install && .venv/bin/droidw demo")
    assert first_block[1].startswith("make test")
    assert lines.index("```bash") < 5


def test_readme_pictures_exist_and_are_small():
    pictures = re.findall(r"!\[[^\]]*\]\(([^)]+)\)", README.read_text())
    assert len(pictures) >= 3
    for rel in pictures:
        path = ROOT / rel
        assert path.is_file(), rel
        assert path.stat().st_size < 300_000, rel


def test_docs_by_purpose_exist_and_their_links_resolve():
    for name in DOCS:
        assert (ROOT / "docs" / name).is_file(), name
    for doc in [README, *(ROOT / "docs" / n for n in DOCS)]:
        for link in re.findall(r"\]\(([^)#]+)(?:#[^)]*)?\)", doc.read_text()):
            if not link.startswith(("http://", "https://")):
                assert (doc.parent / link).exists(), f"{doc.name}: {link}"


def test_every_command_is_in_the_readme_table_and_the_guide():
    from droidw_cli.cli import COMMANDS

    readme, guide = README.read_text(), (ROOT / "docs" / "guide.md").read_text()
    for name in COMMANDS:
        assert f"`droidw {name}" in readme, name
        assert f"droidw {name}" in guide, name


def test_every_run_file_is_in_the_formats_doc():
    from droidw_cli.export.run_files import RUN_FILES

    formats = (ROOT / "docs" / "formats.md").read_text()
    for name in RUN_FILES:
        assert f"### `{name}`" in formats, name
