"""The habits that keep the layout (docs/architecture.md section 1), as a ratchet: modules under
600 lines, functions under 150, Numba kernels with at most 12 positional parameters.

What exceeded a limit was listed below with its size, as debt of issue 40: a listed item could
shrink but not grow, a new one could not appear, and an item within its limit had to leave the
list. The lists are empty now; keep them so. ``ruff`` and ``lint-imports`` (layers, no
import circles) run in ``.ci/run`` beside this file.
"""
import ast
import os


ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
PACKAGES = ("peclet", "peclet_verify")
MODULE_LINES = 600
FUNCTION_LINES = 150
KERNEL_PARAMS = 12

LARGE_MODULES = {
}
LONG_FUNCTIONS = {
}
WIDE_KERNELS = {
}


def _sources():
    for top in PACKAGES:
        for root, _, files in os.walk(os.path.join(ROOT, top)):
            for f in sorted(files):
                if f.endswith(".py"):
                    path = os.path.join(root, f)
                    yield os.path.relpath(path, ROOT).replace(os.sep, "/"), path


def _modules():
    for rel, path in _sources():
        with open(path) as fh:
            yield rel, fh.read().count("\n")


def _functions():
    """(module, function, lines, positional parameters, is a Numba kernel) of every def."""
    for rel, path in _sources():
        with open(path) as fh:
            tree = ast.parse(fh.read())
        for node in ast.walk(tree):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                decorators = [ast.unparse(d) for d in node.decorator_list]
                kernel = any(d.split("(")[0].split(".")[-1] in ("njit", "jit")
                             for d in decorators)
                yield (rel, node.name, node.end_lineno - node.lineno + 1,
                       len(node.args.posonlyargs) + len(node.args.args), kernel)


def _judge(found, debt, limit, what):
    new = {k: v for k, v in found.items() if k not in debt}
    grown = {k: (debt[k], v) for k, v in found.items() if k in debt and v > debt[k]}
    paid = sorted(k for k in debt if k not in found)
    assert not new, f"{what} over {limit}: {new}"
    assert not grown, f"{what} grew past their listed size (listed, now): {grown}"
    assert not paid, f"within {limit} now, remove from the list: {paid}"


def test_modules_stay_under_600_lines():
    _judge({p: n for p, n in _modules() if n > MODULE_LINES}, LARGE_MODULES, MODULE_LINES,
           "modules")


def test_functions_stay_under_150_lines():
    found = {f"{p}:{fn}": n for p, fn, n, _, _ in _functions() if n > FUNCTION_LINES}
    _judge(found, LONG_FUNCTIONS, FUNCTION_LINES, "functions")


def test_kernels_take_at_most_12_positional_parameters():
    found = {f"{p}:{fn}": k for p, fn, _, k, kernel in _functions()
             if kernel and k > KERNEL_PARAMS}
    _judge(found, WIDE_KERNELS, KERNEL_PARAMS, "Numba kernels' positional parameters")


def test_no_debt_is_left():
    """Issue 40 paid every listed item: the lists stay empty (a new excess fails above)."""
    assert not (LARGE_MODULES or LONG_FUNCTIONS or WIDE_KERNELS)
