"""One concept per module, read from the source: no module of the package over 450 lines and no
function over 80 unless its docstring says why (a line "Long because: ...");
no module or function is exempt."""
import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "softcath_ros"
MAX_MODULE_LINES = 450
MAX_FUNCTION_LINES = 80
REASON = "Long because:"


def module_lines() -> dict[str, int]:
    return {p.relative_to(PACKAGE).as_posix(): len(p.read_text().splitlines()) for p in PACKAGE.rglob("*.py")}


def long_functions(source: str, where: str) -> dict[str, int]:
    """``where:name`` -> lines of each function in ``source`` over the limit without a reason."""
    out = {}
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            length = node.end_lineno - node.lineno + 1
            if length > MAX_FUNCTION_LINES and REASON not in (ast.get_docstring(node) or ""):
                out[f"{where}:{node.name}"] = max(length, out.get(f"{where}:{node.name}", 0))
    return out


def test_no_module_over_the_limit():
    over = {m: n for m, n in module_lines().items() if n > MAX_MODULE_LINES}
    assert not over, f"modules over {MAX_MODULE_LINES} lines (split them): {over}"


def test_no_function_over_the_limit_without_a_reason():
    found = {}
    for path in PACKAGE.rglob("*.py"):
        found.update(long_functions(path.read_text(), path.relative_to(PACKAGE).as_posix()))
    assert not found, (f"functions over {MAX_FUNCTION_LINES} lines: split them or say why in the docstring "
                       f"('{REASON} ...'): {found}")


def test_the_function_check_sees_length_and_reason():
    body = "\n".join(f"    x{i} = {i}" for i in range(MAX_FUNCTION_LINES))
    long = f"def f():\n{body}\n"
    assert long_functions(long, "m.py") == {"m.py:f": MAX_FUNCTION_LINES + 1}
    explained = f'def f():\n    """{REASON} one table, row by row."""\n{body}\n'
    assert long_functions(explained, "m.py") == {}
    assert long_functions("def g():\n    return 1\n", "m.py") == {}
