"""The documentation a user reads: its Python examples run, its links resolve, its commands parse, and
the README stays a manual (short, no commit hashes, no issue numbers; history lives in git and the
changelog, results in docs/results.md with their commit named once)."""

from __future__ import annotations

import re
import shlex
from dataclasses import replace
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
BENCHMARKS = ROOT / "benchmarks" / "README.md"
RESULTS = ROOT / "docs" / "results.md"
GUIDE = sorted((ROOT / "docs").rglob("*.md"))
DOCUMENTS = [README, *GUIDE, BENCHMARKS, ROOT / "CHANGELOG.md"]

#: A commit hash: 7-40 hex characters with a letter and a digit, or exactly seven digits (hashes such
#: as 3064828 exist; figures are written with thousands separators and seeds have eight digits).
HASH = re.compile(r"\b(?=[0-9a-f]*[a-f])(?=[0-9a-f]*[0-9])[0-9a-f]{7,40}\b|(?<![\d,.])\b\d{7}\b(?![\d,.])")
ISSUE = re.compile(r"\bissues?\s+#?\d+", re.IGNORECASE)
LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)\)")
FENCE = re.compile(r"^```(\w*)\n(.*?)^```", re.MULTILINE | re.DOTALL)
HEADING = re.compile(r"^#{1,6} +(.+?) *$", re.MULTILINE)

#: The scan budget of an example run by the test: enough to take a step, small enough for CI.
EXAMPLE_SCANS = 2


def _rel(path: Path) -> str:
    return str(path.relative_to(ROOT))


def _without_code(text: str) -> str:
    """The text with fenced blocks blanked, line numbers kept."""
    return FENCE.sub(lambda m: "\n" * m.group(0).count("\n"), text)


def _blocks(path: Path, language: str) -> list[tuple[int, str]]:
    text = path.read_text()
    return [(text[: m.start()].count("\n") + 1, m.group(2)) for m in FENCE.finditer(text) if m.group(1) == language]


def _python_examples() -> list:
    return [
        pytest.param(path, line, code, id=f"{_rel(path)}:{line}")
        for path in [README, *GUIDE]
        for line, code in _blocks(path, "python")
    ]


@pytest.mark.parametrize(("path", "line", "code"), _python_examples())
def test_python_example_runs(path: Path, line: int, code: str, monkeypatch: pytest.MonkeyPatch, tmp_path: Path):
    """Every ```python block of the README and the guide runs as written, each on its own, at a
    scan budget of EXAMPLE_SCANS where it scans."""
    from nbs_env.env import NBSEnv

    original = NBSEnv.__init__

    def tiny(self, *args, **kwargs):
        original(self, *args, **kwargs)
        self.config = replace(self.config, max_scans=min(self.config.max_scans, EXAMPLE_SCANS))

    monkeypatch.setattr(NBSEnv, "__init__", tiny)
    monkeypatch.chdir(tmp_path)  # an example that writes files writes them here
    exec(compile(code, f"{_rel(path)}:{line}", "exec"), {"__name__": "__docs__"})


def test_examples_found():
    """The example test above does not pass by finding nothing."""
    assert len(_python_examples()) >= 5
    assert _blocks(README, "python")


def _slug(heading: str) -> str:
    """GitHub's anchor for a heading."""
    text = re.sub(r"[`*]|\[([^\]]*)\]\([^)]*\)", lambda m: m.group(1) or "", heading).strip().lower()
    return re.sub(r"[^\w\- ]", "", text).replace(" ", "-")


def _broken_links(path: Path) -> list[str]:
    """The relative links (and #anchors) of a Markdown file that do not resolve."""
    broken = []
    for target in LINK.findall(_without_code(path.read_text())):
        if re.match(r"[a-z]+:", target):
            continue  # http(s), mailto: not ours to check offline
        file, _, anchor = target.partition("#")
        resolved = (path.parent / file).resolve() if file else path
        if not resolved.exists():
            broken.append(f"{target}: no such file")
        elif anchor and resolved.suffix == ".md":
            anchors = {_slug(h) for h in HEADING.findall(_without_code(resolved.read_text()))}
            if anchor not in anchors:
                broken.append(f"{target}: no heading with that anchor")
    return broken


@pytest.mark.parametrize("path", DOCUMENTS, ids=_rel)
def test_relative_links_resolve(path: Path):
    """Every relative link (and its #anchor) of the README, the guide and the benchmarks resolves."""
    broken = _broken_links(path)
    assert not broken, f"{_rel(path)}: " + "; ".join(broken)


def test_link_checker_catches_breakage(tmp_path: Path):
    """The checker above flags a missing file and a missing anchor, and passes a good link."""
    (tmp_path / "a.md").write_text("# Title here\n\n## On five_rooms\n")
    page = tmp_path / "b.md"
    page.write_text("[ok](a.md#title-here) [ok](a.md#on-five_rooms) [gone](c.md) [no anchor](a.md#nope)\n")
    assert _broken_links(page) == ["c.md: no such file", "a.md#nope: no heading with that anchor"]
    assert _slug("The paper's §5 against `ours`") == "the-papers-5-against-ours"


def test_readme_is_a_manual():
    """The README: at most 400 lines, no commit hash and no issue number."""
    text = README.read_text()
    assert len(text.splitlines()) <= 400
    assert not HASH.findall(text), HASH.findall(text)
    assert not ISSUE.findall(text), ISSUE.findall(text)


def test_benchmarks_readme_is_short():
    text = BENCHMARKS.read_text()
    assert len(text.splitlines()) <= 250
    assert not HASH.findall(text), HASH.findall(text)
    assert not ISSUE.findall(text), ISSUE.findall(text)


@pytest.mark.parametrize("path", [p for p in GUIDE if p != RESULTS], ids=_rel)
def test_guide_names_no_commit(path: Path):
    text = path.read_text()
    assert not HASH.findall(text), HASH.findall(text)
    assert not ISSUE.findall(text), ISSUE.findall(text)


def _sections(text: str) -> list[str]:
    return re.split(r"^(?=#{1,6} )", text, flags=re.MULTILINE)


def test_results_tables_name_their_commit_once():
    """docs/results.md: every section with a table gives its command, a date and the machine, and
    names the commit it ran at exactly once, before its first table."""
    text = RESULTS.read_text()
    assert not ISSUE.findall(text)
    tables = 0
    for section in _sections(text):
        first_table = re.search(r"^\|.*\|\s*$", section, re.MULTILINE)
        if first_table is None:
            assert not HASH.findall(section), section[:80]
            continue
        tables += 1
        title = section.splitlines()[0]
        hashes = HASH.findall(_without_code(section))
        assert len(hashes) == 1, f"{title}: commits named {hashes}"
        assert section.index(hashes[0]) < first_table.start(), f"{title}: the commit is named after the table"
        assert "```bash" in section, f"{title}: no command"
        assert re.search(r"\b2\d{3}-\d{2}-\d{2}\b", section), f"{title}: no date"
        assert re.search(r"\bcores?\b", section), f"{title}: no machine"
    assert tables >= 3


def test_hash_pattern():
    """The pattern finds hashes of both kinds and leaves figures and seeds alone."""
    assert HASH.findall("at a147219 and 3064828") == ["a147219", "3064828"]
    assert not HASH.findall("2,087,893 points, generated:10000000-10000019, float32, 1e300, 0.1234567")


def _commands(path: Path) -> list[str]:
    """The `nbs ...` command lines of a document's bash blocks, continuation lines joined."""
    lines = []
    for _, block in _blocks(path, "bash"):
        for line in block.replace("\\\n", " ").splitlines():
            for part in line.split("&&"):
                part = part.split(" #")[0].strip()
                if part.startswith("nbs "):
                    lines.append(part)
    return lines


@pytest.mark.parametrize("path", [README, *GUIDE], ids=_rel)
def test_commands_parse(path: Path):
    """Every `nbs` command shown parses with the real command line (a renamed flag fails here)."""
    from train.cli import build_parser
    from train.ppo import build_parser as train_parser

    for command in _commands(path):
        argv = shlex.split(command)[1:]
        try:
            if argv[:1] == ["train"]:
                train_parser().parse_args(argv[1:])
            elif argv != ["--version"]:
                build_parser().parse_args(argv)
        except SystemExit as exc:
            pytest.fail(f"{_rel(path)}: {command!r} does not parse (exit {exc.code})")


def test_readme_shows_every_command():
    """The README's quick start shows scan, compare and train as a user types them."""
    commands = " ".join(_commands(README))
    for word in ("nbs scan", "nbs compare", "nbs train", "nbs scenes"):
        assert word in commands


def test_version_agrees():
    """One version: the package metadata, nbs_env.__version__, `nbs --version` and the changelog."""
    import importlib.metadata

    import nbs_env
    from train.cli import main

    tomllib = pytest.importorskip("tomllib")
    pyproject = tomllib.loads((ROOT / "pyproject.toml").read_text())
    assert pyproject["tool"]["setuptools"]["dynamic"]["version"] == {"attr": "nbs_env.__version__"}
    assert importlib.metadata.version("nbs-env") == nbs_env.__version__
    with pytest.raises(SystemExit) as exit_:
        main(["--version"])
    assert exit_.value.code == 0
    changelog = (ROOT / "CHANGELOG.md").read_text()
    assert re.search(rf"^## \[{re.escape(nbs_env.__version__)}\] - \d{{4}}-\d{{2}}-\d{{2}}$", changelog, re.MULTILINE)


def test_version_printed(capsys: pytest.CaptureFixture):
    import nbs_env
    from train.cli import main

    with pytest.raises(SystemExit):
        main(["--version"])
    assert capsys.readouterr().out.strip() == f"nbs-env {nbs_env.__version__}"


def test_cli_reference_names_every_option():
    """docs/cli.md names every option of every command, so a new flag cannot go undocumented."""
    import argparse

    from train.cli import build_parser
    from train.ppo import build_parser as train_parser

    text = (ROOT / "docs" / "cli.md").read_text()

    def options(parser: argparse.ArgumentParser) -> set[str]:
        found = set()
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                for sub in action.choices.values():
                    found |= options(sub)
            else:
                found |= {o for o in action.option_strings if o.startswith("--") and o != "--help"}
        return found

    missing = sorted(
        o for o in options(build_parser()) | options(train_parser()) if f"`{o}" not in text and f" {o}" not in text
    )
    assert not missing, f"docs/cli.md does not name {missing}"
