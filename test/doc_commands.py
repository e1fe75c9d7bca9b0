"""The commands README.md and docs/ show a user: every `softcath` and `pressure_sweep` line of a fenced
block, as the tests that run them read them (argv from the doc line itself, never a copy)."""
import re
import shlex
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
COMMAND = re.compile(r"(?:\.venv/bin/)?(softcath|python -m softcath_ros\.tools\.pressure_sweep) (.*)")


@dataclass(frozen=True)
class DocCommand:
    doc: str            # path under the repository, e.g. docs/bench.md
    line: int
    tool: str           # softcath, or python -m softcath_ros.tools.pressure_sweep
    argv: tuple         # the words after the tool, its shell comment dropped

    @property
    def where(self) -> str:
        return f"{self.doc}:{self.line}"

    @property
    def text(self) -> str:
        return " ".join((self.tool, *self.argv))


def doc_commands() -> list[DocCommand]:
    """Each command line in a fenced block; a line with a placeholder (``$s`` of a shell loop,
    ``[--optional]``) is not a command as written."""
    found = []
    for path in [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]:
        fenced = False
        for number, line in enumerate(path.read_text().splitlines(), 1):
            if line.startswith("```"):
                fenced = not fenced
                continue
            m = COMMAND.match(line.strip()) if fenced else None
            if m and "$" not in line and "[" not in line:
                found.append(DocCommand(str(path.relative_to(ROOT)), number, m.group(1),
                                        tuple(shlex.split(m.group(2), comments=True))))
    return found


def matching(docs, prefix: str) -> list[DocCommand]:
    """The commands of the pages ``docs`` whose text (tool and words) starts with ``prefix``."""
    return [c for c in doc_commands() if c.doc in docs and c.text.startswith(prefix)]


def doc_argv(docs, prefix: str) -> list[str]:
    """The softcath words of the one command that ``prefix`` names in ``docs`` (the same line on
    several pages counts once)."""
    found = {c.argv for c in matching(docs, prefix)}
    assert len(found) == 1, f"{prefix!r} names {len(found)} different commands in {docs}"
    return list(found.pop())
