"""Every `aacmm ...` command line the README and docs/**/*.md show (in a shell code block, fenced or indented, or
in an inline code span of the text) names a subcommand that exists and only options that subcommand has (checked
against the project's own argparse parser, nothing run), an option with a fixed set of values is given one of them,
and every bundled path the pages name (`examples/...`, `ex/...` after `aacmm examples ex`) exists."""
from __future__ import annotations

import argparse
import re
import shlex
from pathlib import Path

import pytest

from arm_model.cli import build_parser
from arm_model.shipped import SHIPPED_ARMS
from conftest import ROOT

PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]
#: fenced blocks of these languages hold shell lines (the others: toml, python, csv, console output as `text`)
SHELL_LANGUAGES = {"", "sh", "bash", "shell", "console"}
#: a word that starts a command of a shell line
SEPARATORS = {"|", "||", "&&", ";", "{", "}", "(", ")"}


def code_blocks(text: str) -> list[tuple[int, str]]:
    """(first line number, text) of each shell code block of a markdown page: fenced blocks of a shell language (or
    none) and indented blocks (four spaces after a blank line, outside fences)."""
    blocks: list[tuple[int, str]] = []
    lines = text.splitlines()
    i = 0
    while i < len(lines):
        fence = re.match(r"^\s*(```+|~~~+)\s*([\w+-]*)", lines[i])
        if fence:
            end = next((k for k in range(i + 1, len(lines)) if lines[k].strip().startswith(fence.group(1))),
                       len(lines))
            if fence.group(2).lower() in SHELL_LANGUAGES:
                blocks.append((i + 2, "\n".join(lines[i + 1:end])))
            i = end + 1
            continue
        if lines[i].startswith("    ") and lines[i].strip() and (i == 0 or not lines[i - 1].strip()):
            end = i
            while end < len(lines) and (lines[end].startswith("    ") or not lines[end].strip()):
                end += 1
            blocks.append((i + 1, "\n".join(line[4:] for line in lines[i:end])))
            i = end
            continue
        i += 1
    return blocks


def shell_words(line: str) -> list[str]:
    """The words of one shell line, comments dropped; a line shlex cannot split (an unbalanced quote in a
    placeholder) is split on blanks."""
    lexer = shlex.shlex(line, posix=True, punctuation_chars="|&;(){}")
    lexer.whitespace_split = True
    lexer.commenters = "#"
    try:
        return list(lexer)
    except ValueError:
        return line.split("#", 1)[0].split()


def inline_commands(text: str) -> list[tuple[int, str]]:
    """(line number, text) of each inline code span outside the fenced blocks that starts with `aacmm ` (a span may
    run over a line break; a span quoting a message, `aacmm tip: error: ...`, is no command)."""
    outside = re.sub(r"```.*?```", lambda m: "\n" * m.group(0).count("\n"), text, flags=re.S)
    return [(outside[:m.start()].count("\n") + 1, m.group(1).replace("\n", " "))
            for m in re.finditer(r"`((?:\.venv/bin/)?aacmm [^`]+)`", outside)
            if "\n\n" not in m.group(1) and not re.match(r"\S+ \S+:", m.group(1))]


def aacmm_commands() -> list[tuple[str, list[str]]]:
    """(where, the words after `aacmm`) of every aacmm command line of every page's shell code blocks and inline code
    spans; a line ending in a backslash continues on the next."""
    found = []
    for page in PAGES:
        text = page.read_text(encoding="utf-8")
        for start, block in code_blocks(text) + inline_commands(text):
            for offset, line in enumerate(re.sub(r"\\\n", " ", block).splitlines()):
                # a continued line counts from the block's line where it starts (close enough to find it)
                words = shell_words(line)
                for k, word in enumerate(words):
                    starts = k == 0 or words[k - 1] in SEPARATORS
                    if starts and (word == "aacmm" or word.endswith("/aacmm")):
                        rest = words[k + 1:]
                        end = next((j for j, w in enumerate(rest) if w in SEPARATORS), len(rest))
                        found.append((f"{page.relative_to(ROOT)}:{start + offset}", rest[:end]))
    return found


def placeholder(word: str) -> bool:
    """A word that stands for something the reader fills in: a shell variable, `<ids>`, `...`, `FILE`."""
    return "$" in word or "<" in word or word in {"...", "…"} or bool(re.fullmatch(r"[A-Z][A-Z_,|]*", word))


def sub_parsers(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    return {name: sub for action in parser._actions if isinstance(action, argparse._SubParsersAction)
            for name, sub in action.choices.items()}


def options_of(parser: argparse.ArgumentParser) -> dict[str, argparse.Action]:
    return {option: action for action in parser._actions for option in action.option_strings}


@pytest.fixture(scope="module")
def aacmm() -> argparse.ArgumentParser:
    return build_parser()


def check(parser: argparse.ArgumentParser, argv: list[str]) -> list[str]:
    """What is wrong with `aacmm argv` (an optional group `[--opt X]` is checked like the rest)."""
    words = [w.strip("[]") for w in argv]
    words = [w for w in words if w]
    problems: list[str] = []
    # options given before the subcommand (aacmm -q tip ...) are the top parser's
    while words and words[0].startswith("-"):
        if words[0] not in options_of(parser):
            return [f"unknown option {words[0]!r} of aacmm"]
        if words[0] in ("--version", "--help", "-h"):
            return []
        words = words[1:]
    name = "aacmm"
    while words and sub_parsers(parser):
        choices = sub_parsers(parser)
        if placeholder(words[0]):
            return []
        if words[0] not in choices:
            return [f"{name} has no subcommand {words[0]!r} (it has: {', '.join(choices)})"]
        name, parser, words = f"{name} {words[0]}", choices[words[0]], words[1:]
    options = options_of(parser)
    for k, word in enumerate(words):
        if not word.startswith("-") or word == "-" or re.fullmatch(r"-[\d.]+(e-?\d+)?", word) or placeholder(word):
            continue
        option, _, inline = word.partition("=")
        if option not in options:
            problems.append(f"{name}: no option {option!r}")
            continue
        action = options[option]
        value = inline or (words[k + 1] if k + 1 < len(words) else "")
        if action.choices is not None and action.nargs in (None, "?") and value and not placeholder(value) \
                and not value.startswith("-") and value not in action.choices:
            problems.append(f"{name} {option}: {value!r} is not one of {sorted(map(str, action.choices))}")
    return problems


def test_the_pages_show_commands():
    commands = aacmm_commands()
    assert len(commands) > 200, commands
    assert {argv[0] for _, argv in commands if argv} >= {"tip", "calibrate", "close-loop", "simulate", "live"}


def test_every_command_and_option_the_pages_show_exists(aacmm):
    wrong = [f"{where}: {problem}" for where, argv in aacmm_commands() for problem in check(aacmm, argv)]
    assert not wrong, "\n".join(wrong)


def test_the_checker_finds_what_is_wrong(aacmm):
    """The check can fail: an unknown subcommand, an unknown option, a value outside an option's choices."""
    assert check(aacmm, ["calibrate", "p.csv", "a.toml", "--arm", "aacmm7", "-o", "out"]) == []
    assert check(aacmm, ["calibrat", "p.csv"])
    assert check(aacmm, ["calibrate", "p.csv", "--no-such-option", "1"])
    assert check(aacmm, ["calibrate", "p.csv", "--weights", "guessed"])
    assert check(aacmm, ["study", "montecarlo", "c.toml", "--count", "3"])      # --count is study poses'
    assert check(aacmm, ["study", "poses", "p.csv", "a.toml", "--count", "3", "[--holdout", "0.2]"])
    assert check(aacmm, ["tip", "p.csv", "--arm", "$ARM", "-o", "t.csv"]) == []
    assert shell_words("a | aacmm live - --arm x.toml  # comment") == ["a", "|", "aacmm", "live", "-", "--arm",
                                                                       "x.toml"]


#: the folders `aacmm examples DIR` writes, for paths the pages name after that command (`ex/data/...`)
EXAMPLES_DIR_ROOTS = {"campaigns": "examples/campaigns", "data": "examples/data", "live": "examples/live",
                      "docs": "docs"}


#: a path of another project's repository (FIGAROH's examples) is introduced by that repository's name
ANOTHER_REPOSITORY = re.compile(r"github|figaroh", re.I)


def bundled_paths(text: str) -> list[tuple[str, Path]]:
    """(path as written, where it lies in the repository) of every bundled path a page names: `examples/...`, and
    `ex/...` after the README's `aacmm examples ex`."""
    found = []
    for match in re.finditer(r"(?<![\w./-])(examples|ex)/([\w./-]*[\w/])", text):
        root, rest = match.groups()
        if "..." in rest or "*" in rest or ANOTHER_REPOSITORY.search(text[max(0, match.start() - 160):match.start()]):
            continue
        top, _, tail = rest.partition("/")
        if root == "examples":
            where = ROOT / "examples" / rest
        elif top == "arms":
            name = tail.removesuffix(".dh.toml")
            where = ROOT / (SHIPPED_ARMS[name] if name in SHIPPED_ARMS else "urdf" if not tail else tail)
        else:
            where = ROOT / EXAMPLES_DIR_ROOTS.get(top, f"examples/{top}") / tail
        found.append((match.group(0), where))
    return found


def test_every_bundled_path_the_pages_name_exists():
    paths = {page: bundled_paths(page.read_text(encoding="utf-8")) for page in PAGES}
    assert sum(map(len, paths.values())) > 50
    missing = sorted({f"{page.relative_to(ROOT)}: {written}" for page, found in paths.items()
                      for written, where in found if not where.exists()})
    assert not missing, "\n".join(missing)


def test_the_path_check_finds_a_missing_path():
    found = dict(bundled_paths("run `aacmm tip examples/data/no-such/points.csv`, then `cp ex/arms/aacmm7.dh.toml .`; "
                               "(github owner/figaroh-examples, `examples/elsewhere/x.csv`)"))
    assert not found["examples/data/no-such/points.csv"].exists() and found["ex/arms/aacmm7.dh.toml"].exists()
    assert "examples/elsewhere/x.csv" not in found


def slug(heading: str) -> str:
    """GitHub's anchor of a markdown heading: lower case, punctuation but hyphens and underscores dropped, each
    blank a hyphen."""
    return re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-")


def anchors(page: Path) -> set[str]:
    """The anchors of a markdown page's headings (outside fenced blocks), a repeated one numbered as GitHub does."""
    text = re.sub(r"```.*?```", "", page.read_text(encoding="utf-8"), flags=re.S)
    seen: dict[str, int] = {}
    out = set()
    for heading in re.findall(r"^#{1,6} (.+)$", text, flags=re.M):
        base = slug(heading)
        out.add(base if base not in seen else f"{base}-{seen[base]}")
        seen[base] = seen.get(base, 0) + 1
    return out


def page_links(page: Path) -> list[tuple[str, str]]:
    """(target file, anchor) of each relative link of a markdown page: `[text](file.md#anchor)` and `(#anchor)`."""
    text = re.sub(r"```.*?```", "", page.read_text(encoding="utf-8"), flags=re.S)
    return [(target, anchor) for target, anchor in re.findall(r"\]\(([^)\s#:]*)(?:#([^)\s]*))?\)", text)]


def test_every_link_between_the_pages_lands():
    """A link of README.md or docs/**/*.md to a file of the repository names one that exists, and its anchor (if any)
    is a heading of that page: a section moved or renamed keeps its links working."""
    wrong = []
    for page in PAGES:
        for target, anchor in page_links(page):
            where = (page.parent / target).resolve() if target else page
            if not where.exists():
                wrong.append(f"{page.relative_to(ROOT)}: {target} does not exist")
            elif anchor and where.suffix == ".md" and anchor not in anchors(where):
                wrong.append(f"{page.relative_to(ROOT)}: {target}#{anchor} is no heading of {where.name}")
    assert not wrong, "\n".join(wrong)


def test_every_docs_anchor_the_code_names_lands():
    """A page's anchor named in the code, the tests or the pages as a path (`docs/<page>.md#<anchor>`, outside links) is
    a heading of that page."""
    wrong = []
    tops = [top for top in ROOT.iterdir() if top.is_dir() and not top.name.startswith(".")]
    code = [path for top in tops for path in top.rglob("*.py")]
    for path in [*PAGES, *code]:
        for name, anchor in re.findall(r"docs/([\w/-]+\.md)#([\w-]+)", path.read_text(encoding="utf-8")):
            if not (ROOT / "docs" / name).exists() or anchor not in anchors(ROOT / "docs" / name):
                wrong.append(f"{path.relative_to(ROOT)}: docs/{name}#{anchor}")
    assert not wrong, "\n".join(wrong)


#: the guides whose "Command line" section lists the options of their commands
GUIDE_COMMANDS = {"docs/calibration.md": (("calibrate",), ("study", "montecarlo"), ("study", "poses")),
                  "docs/close-loop.md": (("close-loop",),)}


def command_parser(parser: argparse.ArgumentParser, path: tuple[str, ...]) -> argparse.ArgumentParser:
    for name in path:
        parser = sub_parsers(parser)[name]
    return parser


@pytest.mark.parametrize("page", sorted(GUIDE_COMMANDS))
def test_every_option_a_guide_lists_is_its_commands(aacmm, page):
    """Every `--option` the "Command line" section of a guide names (its table of options by purpose, the text under
    it) is an option of the guide's commands: an option renamed or removed shows here, not in a user's shell."""
    text = (ROOT / page).read_text(encoding="utf-8")
    section = text.split("\n## Command line\n", 1)[1].split("\n## ", 1)[0]
    own = {path[0] for path in GUIDE_COMMANDS[page]}
    others = "|".join(re.escape(name) for name in sub_parsers(aacmm) if name not in own)
    section = re.sub(rf"`(?:aacmm )?(?:{others}) [^`]*`", "", section)      # another command's option, said as such
    known = {option for path in GUIDE_COMMANDS[page] for option in options_of(command_parser(aacmm, path))}
    named = set(re.findall(r"(?<![\w-])(--[a-z][a-z0-9-]*)(?![\w<-])", section))
    assert len(named) > 15 and not named - known, sorted(named - known)


def toml_blocks() -> list[tuple[str, str]]:
    """(where, text) of every ```toml block of the pages that is a whole file: an excerpt with an elided line (`...`)
    is not one."""
    found = []
    for page in PAGES:
        text = page.read_text(encoding="utf-8")
        for m in re.finditer(r"```toml\n(.*?)```", text, flags=re.S):
            if not any(line.split("#", 1)[0].strip() in ("...", "…") for line in m.group(1).splitlines()):
                found.append((f"{page.relative_to(ROOT)}:{text[:m.start()].count(chr(10)) + 2}", m.group(1)))
    return found


def read_as_its_kind(text: str, where: str, tmp_path: Path) -> str:
    """Read a page's TOML block with the reader of the file it shows (told by its keys); the kind read."""
    import tomllib

    from arm_model.description import parse_description
    from arm_model.io import parse_artefacts
    from arm_model.live.plan import parse_plan
    from arm_model.urdf_import import load_masses
    keys = tomllib.loads(text)
    if "convention" in keys:
        parse_description(text, where)
        return "description"
    if "link" in keys:
        (tmp_path / "masses.toml").write_text(text, encoding="utf-8")
        load_masses(tmp_path / "masses.toml")
        return "masses"
    if "task" in keys:                       # a campaign: its arm is the reader's own URDF, so only the TOML
        return "campaign"
    if any("points" in f for f in keys.get("feature", [])):
        parse_plan(text, where)
        return "plan"
    parse_artefacts(text, where)
    return "artefacts"


def test_every_toml_block_is_read_by_its_reader(tmp_path):
    """A description, artefacts file, session plan or masses file a page shows is one the toolkit reads: a user
    copies it as a start (the walk-through of a new user found no test of these blocks)."""
    kinds = {}
    for where, text in toml_blocks():
        kinds[where] = read_as_its_kind(text, where, tmp_path)
    assert {"description", "artefacts", "plan", "masses"} <= set(kinds.values()), kinds
