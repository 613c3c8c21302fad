"""The manual points at things that exist: README.md and every page under docs/.

* every relative link (``[text](path)``, ``[text](page.md#heading)``, ``[text](#heading)``)
  names a file or folder inside the repository, and its ``#anchor`` a heading of that page (as
  GitHub spells heading anchors);
* every ``companion SUBCOMMAND [SUBCOMMAND] ... --flag`` in a code block or inline code span
  (and inline code that starts with a subcommand's name, such as ```run --vehicle```) names a
  subcommand of :func:`companion.cli.build_parser` and a flag of that subcommand's parser
  (nested ones too: ``companion mission check``, ``companion pki issue``); ``sitl-plant --flag``
  likewise against :func:`sitl_plant.cli.build_parser`;
* a flag on its own in inline code (```--max-speed```) is a flag of some companion subcommand,
  of sitl-plant, of a benchmark script or of ArduPilot / PX4 SITL;
* every ``make TARGET`` in code is a target of the Makefile;
* docs/flying.md's exit-code table lists every :class:`companion.errors.ExitCode` member with
  its value, README.md stays at most 10 KB, docs/index.md lists every page, and every
  ``docs/...md`` a docstring or comment names exists.

A broken reference fails with ``file:line: what``, one line each, all of them at once. The
checker is itself tested on a page with one broken reference of each kind.
"""

from __future__ import annotations

import argparse
import re
from dataclasses import dataclass
from pathlib import Path

from companion import cli
from companion.errors import ExitCode
from sitl_plant import cli as plant_cli

ROOT = Path(__file__).resolve().parents[2]
README = ROOT / "README.md"
DOCS = ROOT / "docs"
README_LIMIT = 10 * 1024   # bytes


def pages() -> list[Path]:
    return [README, *sorted(DOCS.rglob("*.md"))]


# ---------------------------------------------------------------------------------------------
# Reading a page: code (fenced blocks, inline spans) and prose, with line numbers.

FENCE = re.compile(r"^\s*(```|~~~)")
INLINE = re.compile(r"(`+)(?!`)(.+?)(?<!`)\1(?!`)", re.S)
LINK = re.compile(r"!?\[(?:[^\]\\]|\\.)*\]\(\s*<?([^)\s>]+)>?(?:\s+\"[^\"]*\")?\s*\)")
REF_LINK = re.compile(r"^\s{0,3}\[[^\]]+\]:\s*<?(\S+?)>?(?:\s|$)", re.M)


@dataclass(frozen=True)
class Code:
    line: int
    text: str
    block: bool       # a fenced block's (logical) line, else an inline span


@dataclass(frozen=True)
class Page:
    path: Path
    code: list[Code]
    prose: str        # the page with code blanked out (newlines kept, so offsets give lines)
    headings: list[str]


def read_page(path: Path, text: str | None = None) -> Page:
    text = path.read_text(encoding="utf-8") if text is None else text
    lines = text.split("\n")
    code: list[Code] = []
    outside: list[str] = []
    headings: list[str] = []
    in_block = False
    pending: tuple[int, str] | None = None     # a block line continued with a backslash
    for number, line in enumerate(lines, start=1):
        if FENCE.match(line):
            in_block = not in_block
            outside.append("")
            continue
        if in_block:
            outside.append("")
            start, so_far = pending if pending else (number, "")
            joined = so_far + line
            if joined.rstrip().endswith("\\"):
                pending = (start, joined.rstrip()[:-1] + " ")
            else:
                pending = None
                code.append(Code(start, joined, True))
            continue
        outside.append(line)
        match = re.match(r"^ {0,3}(#{1,6})\s+(.*?)\s*#*\s*$", line)
        if match:
            headings.append(match.group(2))
    prose = "\n".join(outside)
    blanked = list(prose)
    for match in INLINE.finditer(prose):
        line = prose.count("\n", 0, match.start()) + 1
        code.append(Code(line, " ".join(match.group(2).split()), False))
        for i in range(match.start(), match.end()):
            if blanked[i] != "\n":
                blanked[i] = " "
    return Page(path, code, "".join(blanked), headings)


def where(page: Page, line: int) -> str:
    try:
        name = page.path.relative_to(ROOT)
    except ValueError:
        name = page.path
    return f"{name}:{line}"


# ---------------------------------------------------------------------------------------------
# Links and anchors.

def anchors(headings: list[str]) -> set[str]:
    """GitHub's heading anchors: lower case, punctuation dropped, spaces as hyphens, -1, -2 ... for
    repeats."""
    seen: dict[str, int] = {}
    out = set()
    for heading in headings:
        text = re.sub(r"\[([^\]]*)\]\([^)]*\)", r"\1", heading)      # a link's text only
        slug = re.sub(r"[^\w\- ]", "", text.lower()).replace(" ", "-")
        n = seen.get(slug, 0)
        seen[slug] = n + 1
        out.add(slug if n == 0 else f"{slug}-{n}")
    return out


def link_problems(page: Page, root: Path = ROOT) -> list[str]:
    problems = []
    targets = [(m.start(), m.group(1)) for m in LINK.finditer(page.prose)]
    targets += [(m.start(), m.group(1)) for m in REF_LINK.finditer(page.prose)]
    for offset, target in targets:
        line = page.prose.count("\n", 0, offset) + 1
        if re.match(r"^[a-z][a-z0-9+.-]*:", target, re.I):       # https:, mailto:, ...
            continue
        path_part, _, anchor = target.partition("#")
        dest = (page.path.parent / path_part).resolve() if path_part else page.path
        if path_part and not dest.is_relative_to(root.resolve()):
            problems.append(f"{where(page, line)}: link {target!r} leaves the repository")
            continue
        if not dest.exists():
            problems.append(f"{where(page, line)}: link {target!r}: no such file")
            continue
        if anchor:
            if dest.suffix != ".md" or dest.is_dir():
                problems.append(f"{where(page, line)}: link {target!r}: an anchor into a "
                                "file that is not a page")
                continue
            heads = read_page(dest).headings if dest != page.path else page.headings
            if anchor not in anchors(heads):
                problems.append(f"{where(page, line)}: link {target!r}: no heading "
                                f"#{anchor} in {dest.name}")
    return problems


# ---------------------------------------------------------------------------------------------
# Commands and their flags.

COMPANION = re.compile(r"(?<![\w.-])companion(?=\s+\S)")
PLANT = re.compile(r"(?<![\w.-])(?:sitl-plant|python -m sitl_plant)(?=\s+\S)")
MAKE = re.compile(r"(?<![\w.$/-])make\s+(\S+)")
STOP_TOKENS = {"|", "||", "&&", ";", ">", ">>", "<", "2>", "&"}


def subparsers(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return dict(action.choices)
    return {}


def option_strings(parser: argparse.ArgumentParser) -> set[str]:
    return {s for action in parser._actions for s in action.option_strings}


def words_after(text: str) -> list[str]:
    """The words of one command line, up to where the shell (or a comment, or prose) ends it."""
    out = []
    for word in text.split():
        if word in STOP_TOKENS or word.startswith(("#", "(", "`")):
            break
        if word.endswith(";"):
            out.append(word[:-1])
            break
        out.append(word)
    return out


def flags_in(words: list[str]) -> list[str]:
    """``--flag`` / ``-f`` words, synopsis brackets, ``=value`` and punctuation stripped;
    ``--a/--b`` is two flags."""
    out = []
    for word in words:
        for part in word.strip("[]{}(),.:;'\"").split("/"):
            part = part.strip("[]{}(),.:;'\"").split("=", 1)[0]
            if re.fullmatch(r"--[a-z0-9][a-z0-9-]*|-[a-zA-Z]", part):
                out.append(part)
    return out


def check_words(parser: argparse.ArgumentParser, prog: str, words: list[str],
                place: str) -> list[str]:
    """Walk ``words`` down the parser's subcommands, then hold each flag against the parser
    reached (a parser whose subcommand is not named: any of its subcommands' flags)."""
    names = [prog]
    i = 0
    while i < len(words) and subparsers(parser).get(words[i]) is not None:
        parser = subparsers(parser)[words[i]]
        names.append(words[i])
        i += 1
    rest = words[i:]
    flags = flags_in(rest)
    if not flags:
        return []
    known = option_strings(parser)
    children = subparsers(parser)
    if children:
        if rest and re.fullmatch(r"[a-z][a-z0-9-]*", rest[0]) and rest[0] not in children:
            return [f"{place}: {' '.join(names)} has no subcommand {rest[0]!r}"]
        for child in children.values():
            known |= option_strings(child)
    return [f"{place}: {' '.join(names)} has no flag {flag}" for flag in flags
            if flag not in known]


def command_problems(page: Page) -> list[str]:
    companion = cli.build_parser()
    plant = plant_cli.build_parser()
    commands = set(subparsers(companion))
    problems = []
    for code in page.code:
        place = where(page, code.line)
        for match in COMPANION.finditer(code.text):
            words = words_after(code.text[match.end():])
            if words and re.fullmatch(r"[a-z][a-z0-9-]*", words[0]) and words[0] not in commands:
                if flags_in(words[1:]):
                    problems.append(f"{place}: companion has no subcommand {words[0]!r}")
                continue
            problems += check_words(companion, "companion", words, place)
        for match in PLANT.finditer(code.text):
            problems += check_words(plant, "sitl-plant", words_after(code.text[match.end():]),
                                    place)
        if not code.block:        # inline code naming a subcommand: `run --vehicle`
            words = words_after(code.text)
            if words and words[0] in commands and not COMPANION.search(code.text):
                problems += check_words(companion, "companion", words, place)
    return problems


# Flags of programs that are not ours, named in the docs as inline code: ArduPilot SITL's
# (``--home``, ``--serial2``, ``-I``) and PX4's (``-i``).
OTHER_PROGRAMS_FLAGS = {"--home", "--serial2", "-I", "-i"}


def every_flag(parser: argparse.ArgumentParser) -> set[str]:
    flags = option_strings(parser)
    for child in subparsers(parser).values():
        flags |= every_flag(child)
    return flags


def benchmark_flags() -> set[str]:
    return {flag for path in sorted((ROOT / "benchmarks").glob("*.py"))
            for flag in re.findall(r"add_argument\(\s*\"(-[-\w]+)\"", path.read_text())}


def bare_flag_problems(page: Page, known: set[str]) -> list[str]:
    """Inline code that is a flag on its own (```--max-speed```): a flag of some companion
    subcommand, of sitl-plant, of a benchmark script, or of ArduPilot / PX4 SITL."""
    problems = []
    for code in page.code:
        words = code.text.split()
        if code.block or not words or not words[0].startswith("-"):
            continue
        problems += [f"{where(page, code.line)}: no command has the flag {flag}"
                     for flag in flags_in(words_after(code.text)) if flag not in known]
    return problems


def known_flags() -> set[str]:
    return (every_flag(cli.build_parser()) | every_flag(plant_cli.build_parser())
            | benchmark_flags() | OTHER_PROGRAMS_FLAGS)


def make_targets(makefile: Path = ROOT / "Makefile") -> set[str]:
    targets = set()
    for line in makefile.read_text().splitlines():
        match = re.match(r"^([A-Za-z0-9_.-][A-Za-z0-9_. -]*):(?!=)", line)
        if match and not line.startswith("\t"):
            targets |= set(match.group(1).split())
    return targets - {".PHONY"}


def make_problems(page: Page, targets: set[str]) -> list[str]:
    problems = []
    for code in page.code:
        for match in MAKE.finditer(code.text):
            target = match.group(1).strip("`'\".,;:)")
            if "=" in target or target.startswith("-"):
                continue
            if target not in targets:
                problems.append(f"{where(page, code.line)}: the Makefile has no target "
                                f"{target!r}")
    return problems


def all_problems(page: Page) -> list[str]:
    return link_problems(page) + command_problems(page) + make_problems(page, make_targets())


# ---------------------------------------------------------------------------------------------
# The manual.

def report(problems: list[str]) -> str:
    return f"{len(problems)} broken reference(s):\n" + "\n".join(problems)


def test_links_resolve():
    problems = [p for path in pages() for p in link_problems(read_page(path))]
    assert not problems, report(problems)


def test_companion_commands_and_flags_exist():
    problems = [p for path in pages() for p in command_problems(read_page(path))]
    assert not problems, report(problems)


def test_bare_flags_exist():
    known = known_flags()
    problems = [p for path in pages() for p in bare_flag_problems(read_page(path), known)]
    assert not problems, report(problems)


def test_make_targets_exist():
    targets = make_targets()
    assert {"demo", "test"} <= targets
    problems = [p for path in pages() for p in make_problems(read_page(path), targets)]
    assert not problems, report(problems)


def test_the_manual_names_commands_at_all():
    """The checks above see the commands: a parser change that made them see nothing would
    pass them vacuously."""
    names = [m.group(0) for path in pages() for code in read_page(path).code
             for m in COMPANION.finditer(code.text)]
    assert len(names) > 80


def test_readme_is_short_and_keeps_its_two_commands():
    text = README.read_text(encoding="utf-8")
    assert len(text.encode()) <= README_LIMIT, f"README.md is {len(text.encode())} bytes"
    assert "make demo" in text and "make test" in text


DOCS_PATH = re.compile(r"(?<![\w/.-])docs/(?:[\w-]+/)*[\w-]+\.md")


def test_pages_the_code_names_exist():
    """``docs/...md`` named in a docstring or comment (companion/, sitl_plant/, deploy/, tests/)
    is a page that exists."""
    problems = []
    sources = [p for folder in ("companion", "sitl_plant", "deploy", "tests", "testbed", "benchmarks")
               for p in sorted((ROOT / folder).rglob("*")) if p.is_file()
               and p.suffix in {".py", ".service", ".toml", ".sysusers", ""}]
    for path in sources:
        for number, line in enumerate(path.read_text(errors="replace").splitlines(), start=1):
            for match in DOCS_PATH.finditer(line):
                if not (ROOT / match.group(0)).is_file():
                    problems.append(f"{path.relative_to(ROOT)}:{number}: no page {match.group(0)}")
    assert not problems, report(problems)


def test_index_lists_every_page():
    index = read_page(DOCS / "index.md")
    linked = {(index.path.parent / m.group(1).partition("#")[0]).resolve()
              for m in LINK.finditer(index.prose)}
    missing = [str(p.relative_to(ROOT)) for p in sorted(DOCS.rglob("*.md"))
               if p.name != "index.md" and p.resolve() not in linked]
    assert not missing, f"docs/index.md does not list: {', '.join(missing)}"


def test_exit_code_table_is_the_enum():
    """docs/flying.md's exit-code table: one row per ExitCode member, with its value."""
    text = (DOCS / "flying.md").read_text(encoding="utf-8")
    rows = dict(re.findall(r"^\|\s*`([A-Z_]+)`\s*\|\s*(\d+)\s*\|", text, re.M))
    assert rows == {name: str(int(member)) for name, member in ExitCode.__members__.items()}


# ---------------------------------------------------------------------------------------------
# The checker itself.

BROKEN = """\
# A page

## Some heading

See [the other page](missing.md), [a heading](#some-heading) and [no such](#nowhere).
Outside: [escape](../../../etc/passwd). Fine: [site](https://example.org/x).

```sh
companion run --connect udpin:0.0.0.0:14550 --no-such-flag \\
    --mission m.toml --also-missing
companion mission check --vehicle v.toml m.toml
companion mission checks m.toml --vehicle v.toml
companion pki issue site rover1 --rolle rover
sitl-plant --speedup 5 --warp 9
make demo
make flyaway
```

Inline: `companion tune --rate 40 --bogus`, `run --vehicle v.toml --vehicel v.toml`, and
`companion frobnicate --x`; prose that says companion --nothing is not code; `--max-speed` is
a flag, `--max-sped` is none.
"""


def test_checker_reports_file_and_line_of_each_broken_reference(tmp_path):
    page_path = tmp_path / "page.md"
    page_path.write_text(BROKEN)
    page = read_page(page_path)
    problems = (link_problems(page, root=tmp_path) + command_problems(page)
                + make_problems(page, make_targets()) + bare_flag_problems(page, known_flags()))
    here = str(page_path)
    expected = [
        f"{here}:5: link 'missing.md': no such file",
        f"{here}:5: link '#nowhere': no heading #nowhere in page.md",
        f"{here}:6: link '../../../etc/passwd' leaves the repository",
        f"{here}:9: companion run has no flag --no-such-flag",
        f"{here}:9: companion run has no flag --also-missing",
        f"{here}:12: companion mission has no subcommand 'checks'",
        f"{here}:13: companion pki issue has no flag --rolle",
        f"{here}:14: sitl-plant has no flag --warp",
        f"{here}:16: the Makefile has no target 'flyaway'",
        f"{here}:19: companion tune has no flag --bogus",
        f"{here}:19: companion run has no flag --vehicel",
        f"{here}:20: companion has no subcommand 'frobnicate'",
        f"{here}:21: no command has the flag --max-sped",
    ]
    assert sorted(problems) == sorted(expected)
