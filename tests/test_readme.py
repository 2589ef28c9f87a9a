"""README.md's Python examples run as written, and every value a comment shows after an expression
(`wenv.gloss(paint, 60)   # 91.39 GU`) is what the expression gives, to the digits shown: the README
is what a user copies first, so it must stay true as the code changes.  The Blender scripting
example runs in tests/test_addon.py (it needs the registered add-on)."""
import ast
import io
import re
import math
import pathlib
import sys
import tokenize

import numpy as np
import pytest

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1]))
from tests.helpers import merl_files  # noqa: E402
import wenv  # noqa: E402
import conftest  # noqa: E402
from conftest import bundled_hdri_dir, python_blocks, random_pairs, readme_block  # noqa: E402


def leading_literal(comment):
    """The value a comment shows first -- a number, or a bracketed literal in which `...` stands
    for keys left out -- as an expression's source text; None when the comment starts with words."""
    text = comment.lstrip("#").strip()
    if text[:1] in "([{":
        depth = 0
        for end, ch in enumerate(text):
            depth += ch in "([{"
            depth -= ch in ")]}"
            if depth == 0:
                return text[:end + 1].replace(", ...", "")
        return None
    number = ""
    for ch in text:
        if not (ch.isdigit() or ch in ".-+e"):
            break
        number += ch
    return number if number[:1].isdigit() else None


def comments_by_line(source):
    return {tok.start[0]: tok.string for tok in tokenize.generate_tokens(io.StringIO(source).readline)
            if tok.type == tokenize.COMMENT}


def disagreement(value, node, text):
    """Why `value` does not show as the literal `node` (parsed from `text`), or None if it does: a
    number to the decimals written, containers element by element, a dict on the keys shown."""
    if isinstance(node, (ast.Tuple, ast.List)):
        if not hasattr(value, "__len__"):
            return f"{value!r} is not a sequence"
        value = list(value)
        if len(value) != len(node.elts):
            return f"{len(value)} values, {len(node.elts)} shown"
        for v, n in zip(value, node.elts):
            why = disagreement(v, n, text)
            if why:
                return why
        return None
    if isinstance(node, ast.Dict):
        if not isinstance(value, dict):
            return f"{value!r} is not a dict"
        for k, n in zip(node.keys, node.values):
            if k.value not in value:
                return f"no key {k.value!r}"
            why = disagreement(value[k.value], n, text)
            if why:
                return f"{k.value!r}: {why}"
        return None
    shown = ast.literal_eval(node)
    if isinstance(shown, float) and not isinstance(shown, bool):
        written = ast.get_source_segment(text, node)
        mantissa = written.lower().split("e")[0]
        decimals = len(mantissa.split(".")[1]) if "." in mantissa else 0
        exponent = int(written.lower().split("e")[1]) if "e" in written.lower() else 0
        half_unit = 0.5 * 10.0 ** (exponent - decimals)
        ok = isinstance(value, (int, float, np.floating)) and abs(float(value) - shown) <= half_unit * (1 + 1e-9)
        return None if ok else f"{value!r} is not {written}"
    return None if value == shown and type(value) is type(shown) else f"{value!r} is not {shown!r}"


def run_checked(source, namespace):
    """Runs the block statement by statement; returns how many expression values its comments show,
    each checked."""
    comments = comments_by_line(source)
    checked = 0
    for stmt in ast.parse(source).body:
        code = ast.get_source_segment(source, stmt)
        literal = leading_literal(comments.get(stmt.end_lineno, "#"))
        if not isinstance(stmt, ast.Expr) or literal is None:
            exec(compile(code, "README.md", "exec"), namespace)
            continue
        value = eval(compile(code, "README.md", "eval"), namespace)
        node = ast.parse(literal, mode="eval").body
        why = disagreement(value, node, literal)
        assert why is None, f"README.md: `{code}` shows {literal}, gives {value!r} ({why})"
        checked += 1
    return checked


def test_the_checker_catches_a_wrong_figure():
    """The checker itself: a value off by more than its last digit, a missing key and a wrong
    length fail; rounding within the digits shown passes."""
    ns = {"x": 91.394, "d": {"level": 3, "met": True}}
    assert run_checked("x   # 91.39 GU\nd   # {'level': 3, ...}\n", ns) == 2
    for wrong in ("x   # 91.38 GU\n", "x   # (91.39, 1)\n", "d   # {'levels': 3, ...}\n", "d   # {'met': 1}\n"):
        with pytest.raises(AssertionError, match="README.md"):
            run_checked(wrong, ns)
    assert run_checked("x   # the reading\n", ns) == 0


@pytest.fixture(scope="module")
def api_namespace():
    """The Python API block run on a small sphere's vertices under the bundled sunset.exr (the
    name it loads), with the names it leaves to the reader defined."""
    threads = wenv.get_num_threads()
    normals, view_dirs = random_pairs(200, seed=5)
    eye = np.array([3.0, 1.0, 1.5])
    forward = -eye / np.linalg.norm(eye)
    right = np.cross(forward, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    view = np.eye(4)
    view[:3, :3] = np.stack([right, np.cross(right, forward), -forward])
    view[:3, 3] = -view[:3, :3] @ eye
    f, near, far = 1.0 / math.tan(math.radians(20.0)), 0.1, 50.0
    proj = np.array([[f, 0, 0, 0], [0, f, 0, 0], [0, 0, (far + near) / (near - far), 2 * far * near / (near - far)],
                     [0, 0, -1, 0]])
    ns = {"normals": normals, "view_dirs": view_dirs, "positions": normals.copy(), "eye": eye, "vp": proj @ view,
          "other_material": wenv.Lambert((0.5, 0.5, 0.5))}
    with pytest.MonkeyPatch.context() as mp:
        mp.chdir(bundled_hdri_dir())
        checked = run_checked(readme_block("import numpy as np, wenv"), ns)
    wenv.set_num_threads(threads)
    ns["checked"] = checked
    return ns


def test_api_block_runs_and_shows_true_values(api_namespace):
    ns = api_namespace
    assert ns["checked"] == 3  # METHODS, the ranges, alpha_from_roughness
    n = len(ns["normals"])
    assert ns["rgb"].shape == (n, 3) and np.isfinite(ns["rgb"]).all()
    assert ns["k"] == n  # the refinement loop reached every vertex
    assert ns["truth"].shape == (n, 3) and (ns["truth"] > 0).any()


def test_auto_block_shows_true_values(api_namespace):
    ns = dict(api_namespace, mesh_normals=api_namespace["normals"])
    assert run_checked(readme_block("shader = wenv.Shader(env, mat, quality=\"auto\""), ns) == 1
    assert ns["shader"].stats["auto"]["predicted_error"] <= 0.01


def test_principled_block_runs(api_namespace):
    ns = dict(api_namespace)
    assert run_checked(readme_block("paint = wenv.Principled("), ns) == 5
    assert ns["metal"].inputs["coat_weight"] == 1.0


def test_tabulated_block_runs(api_namespace, tmp_path, monkeypatch):
    """Its MERL file is written here from a Cook-Torrance lobe at MERL's sample positions (16 x 16 x
    32, a size load_brdf reads like the full one)."""
    ns = dict(api_namespace, table=merl_files.tabulate(merl_files.cook_torrance(0.2), 16, 16, 32))
    merl_files.write_merl(tmp_path / "gold-metallic-paint.binary", ns["table"])
    monkeypatch.chdir(tmp_path)
    run_checked(readme_block("mat = wenv.load_brdf("), ns)
    assert tuple(ns["mat"].shape) == (16, 16, 32)


def test_glossmeter_block_shows_true_readings():
    assert run_checked(readme_block("import wenv\n\npaint = "), {}) == 5


def test_every_python_block_is_run():
    """A Python block added to the README gets a test: these are the blocks run here, the Blender
    scripting one (tests/test_addon.py) and the extension's installation (tests/test_addon_install.py
    runs the same call on the zip it builds)."""
    run = ("import numpy as np, wenv", 'shader = wenv.Shader(env, mat, quality="auto"', "paint = wenv.Principled(",
           "mat = wenv.load_brdf(", "import wenv\n\npaint = ", "import bpy\nscene = bpy.context.scene",
           "import bpy\nbpy.ops.extensions.package_install_files(")
    blocks = python_blocks()
    assert [sum(b.startswith(first) for first in run) for b in blocks] == [1] * len(blocks)
    assert len(blocks) == len(run)


def test_every_name_the_readme_gives_exists(api_namespace):
    """Every `wenv.<name>` in the README's text is the module's or one of the add-on's operators, and
    every `stats["key"]` it names is in a Shader's stats."""
    text = conftest.README.read_text(encoding="utf-8")
    operators_py = conftest.README.parent / "addon" / "operators.py"
    operators = re.findall(r'bl_idname = "wenv\.(\w+)"', operators_py.read_text(encoding="utf-8"))
    names = set(re.findall(r"(?<![\w.])wenv\.([A-Za-z_]\w*)", text))
    assert len(names) >= 30 and len(operators) == 8
    assert sorted(n for n in names if not hasattr(wenv, n) and n not in operators) == []
    keys = set(re.findall(r'stats\["(\w+)"\]', text))
    ns = api_namespace
    stats = {**ns["shader"].stats, **wenv.Shader(ns["env"], ns["mat"], quality="auto").stats}
    assert "next_vertex" in keys and sorted(k for k in keys if k not in stats) == []
