"""The docs' shape: every page under docs/ short enough to read (250 lines), every table row readable
in a terminal (160 characters), every `benchmarks/results/...` file a page names committed, and every
relative markdown link (file and #anchor) resolving."""
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
MAX_LINES = 250
MAX_ROW = 160
RESULT = re.compile(r"benchmarks/results/([A-Za-z0-9_.{},*\-]+)")
LINK = re.compile(r"\[[^\]]*\]\(([^)\s]+)\)")


def pages() -> list[Path]:
    return sorted(DOCS.rglob("*.md"))


def rel(path: Path) -> str:
    return str(path.relative_to(ROOT))


def outside_code(path: Path):
    """(line number, line) of each line outside fenced code blocks."""
    fenced = False
    for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
        if line.lstrip().startswith("```"):
            fenced = not fenced
            continue
        if not fenced:
            yield number, line


def anchors(path: Path) -> set[str]:
    """GitHub's heading anchors: lower case, punctuation dropped, spaces to hyphens, repeats numbered."""
    seen: dict[str, int] = {}
    out = set()
    for _, line in outside_code(path):
        m = re.match(r"#{1,6}\s+(.*)", line)
        if not m:
            continue
        slug = re.sub(r"[^\w\- ]", "", m.group(1).strip().lower()).replace(" ", "-")
        n = seen.get(slug, 0)
        seen[slug] = n + 1
        out.add(slug if n == 0 else f"{slug}-{n}")
    return out


def expand(pattern: str) -> list[str]:
    """`a_{1,2}.json` -> [a_1.json, a_2.json]; globs stay globs."""
    m = re.search(r"\{([^{}]*)\}", pattern)
    if not m:
        return [pattern]
    return [x for alt in m.group(1).split(",") for x in expand(pattern[:m.start()] + alt + pattern[m.end():])]


def test_the_docs_exist():
    assert len(pages()) > 10


@pytest.mark.parametrize("page", pages(), ids=rel)
def test_no_page_is_over_250_lines(page):
    n = len(page.read_text(encoding="utf-8").splitlines())
    assert n <= MAX_LINES, f"{rel(page)} has {n} lines (at most {MAX_LINES}: split it by topic)"


@pytest.mark.parametrize("page", pages(), ids=rel)
def test_every_table_row_fits_a_terminal(page):
    long = [f"{rel(page)}:{n}: {len(line)} characters" for n, line in outside_code(page)
            if line.lstrip().startswith("|") and len(line) > MAX_ROW]
    assert not long, "table rows over %d characters (move prose into a list):\n%s" % (MAX_ROW, "\n".join(long))


@pytest.mark.parametrize("page", pages(), ids=rel)
def test_every_named_result_file_is_committed(page):
    missing = []
    for n, line in enumerate(page.read_text(encoding="utf-8").splitlines(), 1):
        for name in RESULT.findall(line):
            name = name.rstrip(".,")
            for pattern in expand(name):
                if not pattern or pattern.endswith("/") or re.match(r"[A-Z]+\b", pattern):
                    continue   # a folder, or a placeholder (NAME.json)
                if "." not in pattern:
                    pattern += ".*"   # a stem: benchmarks/results/ladder_chart
                hits = list((ROOT / "benchmarks/results").glob(pattern)) if "*" in pattern \
                    else [ROOT / "benchmarks/results" / pattern]
                if not any(h.exists() for h in hits):
                    missing.append(f"{rel(page)}:{n}: benchmarks/results/{pattern}")
    assert not missing, "result files named but not committed:\n" + "\n".join(missing)


@pytest.mark.parametrize("page", pages(), ids=rel)
def test_every_relative_link_resolves(page):
    broken = []
    for n, line in outside_code(page):
        for target in LINK.findall(line):
            if re.match(r"[a-z]+:", target):   # http:, https:, mailto:
                continue
            file, _, anchor = target.partition("#")
            dest = page if not file else (page.parent / file).resolve()
            if not dest.exists():
                broken.append(f"{rel(page)}:{n}: {target} (no such file)")
            elif anchor and dest.suffix == ".md" and anchor not in anchors(dest):
                broken.append(f"{rel(page)}:{n}: {target} (no such heading)")
    assert not broken, "broken links:\n" + "\n".join(broken)


def test_the_shape_checks_can_fail(tmp_path):
    """The checks above find what they look for (a page of each fault)."""
    page = tmp_path / "p.md"
    page.write_text("# A title\n\n| " + "x" * 200 + " |\n\n[gone](nowhere.md) [here](#a-title) [no](#b)\n")
    assert "a-title" in anchors(page)
    assert [len(line) > MAX_ROW for _, line in outside_code(page) if line.startswith("|")] == [True]
    assert expand("r_{1,2}.json") == ["r_1.json", "r_2.json"]
    targets = [t for _, line in outside_code(page) for t in LINK.findall(line)]
    assert targets == ["nowhere.md", "#a-title", "#b"]
