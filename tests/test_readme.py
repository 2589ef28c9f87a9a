"""The Python examples of README.md and docs/*.md run as written, and every value a comment shows
after an expression (`wenv.gloss(paint, 60)   # 91.39 GU`) is what the expression gives, to the
digits shown: the documentation is what a user copies first, so it must stay true as the code
changes.  The Blender scripting examples run in tests/test_addon.py (they need the registered
add-on).  Also: every name the documentation gives exists, every relative link between its files
resolves, and every command block names scripts that exist."""
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
from tests.helpers.meshes import uv_sphere  # noqa: E402
import wenv  # noqa: E402
import conftest  # noqa: E402
from conftest import (bundled_hdri_dir, fenced_blocks, markdown_files, python_blocks, random_pairs,  # noqa: E402
                      readme_block)

ROOT = conftest.ROOT
# The first lines of each example, as readme_block finds it (a prefix only one block has).
QUICK_START = 'import numpy as np, wenv\n\nenv = wenv.load_environment("sunset.exr")'
API = 'import numpy as np, wenv\n\nenv = wenv.load_environment("sunset.exr", projection='
AUTO = 'shader = wenv.Shader(env, mat, quality="auto"'
PRINCIPLED = "paint = wenv.Principled("
TABULATED = "mat = wenv.load_brdf("
GLOSSMETER = "import wenv\n\npaint = "
OCCLUDERS = "occluders = wenv.Occluders("
SWEEPS = "import wenv, wenv_sweep\n"
LAMPS = "import numpy as np, wenv\n\nm = np.eye(4)"
BENT = "import numpy as np, wenv\n\nsky = "
NOISE = "fac, colour = wenv.noise_texture(points, "


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


def run_checked(source, namespace, name="README.md"):
    """Runs the block statement by statement; returns how many expression values its comments show,
    each checked.  `name` is the file the block is from, for messages."""
    comments = comments_by_line(source)
    checked = 0
    for stmt in ast.parse(source).body:
        code = ast.get_source_segment(source, stmt)
        literal = leading_literal(comments.get(stmt.end_lineno, "#"))
        if not isinstance(stmt, ast.Expr) or literal is None:
            exec(compile(code, name, "exec"), namespace)
            continue
        value = eval(compile(code, name, "eval"), namespace)
        node = ast.parse(literal, mode="eval").body
        why = disagreement(value, node, literal)
        assert why is None, f"{name}: `{code}` shows {literal}, gives {value!r} ({why})"
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


def test_quick_start_runs_and_shows_true_values(monkeypatch):
    """The README's Python quick start, as written, in the folder of Blender's bundled sunset.exr
    (the name it loads): it shades its sphere and shows the shape and the gloss readings."""
    monkeypatch.chdir(bundled_hdri_dir())
    ns = {}
    assert run_checked(readme_block(QUICK_START), ns) == 2  # the shape, the gloss readings
    rgb, normals = ns["rgb"], ns["normals"]
    assert np.isfinite(rgb).all() and (rgb >= 0).all()
    facing = normals @ (np.array(ns["eye"]) / np.linalg.norm(ns["eye"])) > 0.3
    assert (rgb[facing].max(axis=1) > 0).all()  # what faces the eye is lit


@pytest.fixture(scope="module")
def api_namespace():
    """The Python API block (docs/python.md) run on a small sphere's vertices under the bundled sunset.exr (the
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
          "other_material": wenv.Lambert((0.5, 0.5, 0.5)),
          "colours": np.full((len(normals), 3), 0.5, np.float32),  # textures read at the vertices
          "r": np.linspace(0.1, 0.7, len(normals), dtype=np.float32),
          "m": np.linspace(0.0, 1.0, len(normals), dtype=np.float32)}
    with pytest.MonkeyPatch.context() as mp:
        mp.chdir(bundled_hdri_dir())
        checked = run_checked(readme_block(API), ns, "docs/python.md")
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
    assert ns["textured"].shape == (n, 3) and np.isfinite(ns["textured"]).all()


def test_auto_block_shows_true_values(api_namespace):
    ns = dict(api_namespace, mesh_normals=api_namespace["normals"])
    assert run_checked(readme_block(AUTO), ns, "docs/performance.md") == 1
    assert ns["shader"].stats["auto"]["predicted_error"] <= 0.01


def test_principled_block_runs(api_namespace):
    ns = dict(api_namespace)
    assert run_checked(readme_block(PRINCIPLED), ns, "docs/principled.md") == 5
    assert ns["metal"].inputs["coat_weight"] == 1.0


def test_tabulated_block_runs(api_namespace, tmp_path, monkeypatch):
    """Its MERL file is written here from a Cook-Torrance lobe at MERL's sample positions (16 x 16 x
    32, a size load_brdf reads like the full one)."""
    ns = dict(api_namespace, table=merl_files.tabulate(merl_files.cook_torrance(0.2), 16, 16, 32))
    merl_files.write_merl(tmp_path / "gold-metallic-paint.binary", ns["table"])
    monkeypatch.chdir(tmp_path)
    run_checked(readme_block(TABULATED), ns, "docs/measured_brdfs.md")
    assert tuple(ns["mat"].shape) == (16, 16, 32)


def test_glossmeter_block_shows_true_readings():
    assert run_checked(readme_block(GLOSSMETER), {}, "docs/glossmeter.md") == 5


def test_occluders_block_runs():
    """docs/python.md's shadows block on a roof and two ground points (one under the roof), all of
    them shaded: the point under the roof is blocked overhead, and both the shading and the reference
    are darker there than in the open."""
    roof = [[-1, -1, 1], [1, -1, 1], [1, 1, 1], [-1, 1, 1]]
    ns = {"wenv": wenv, "np": np, "env": wenv.Environment(np.ones((32, 64, 3), np.float32)), "mat": wenv.Lambert(0.5),
          "scene_positions": np.float32(roof + [[0, 0, 0], [5, 0, 0]]), "scene_triangles": np.array([[0, 1, 2], [0, 2, 3]]),
          "normals": np.float32([[0, 0, 1]] * 6), "view_dirs": np.float32([[0, 0.3, 1]] * 6)}
    ns.update(positions=ns["scene_positions"], origins=ns["scene_positions"], directions=ns["normals"],
              points=ns["scene_positions"], corner_normals=np.float32([[0, 0, 1]] * 6))
    # the roof moved sideways: its two triangles changed
    ns.update(new_scene_positions=ns["scene_positions"] + np.float32([[0.3, 0, 0]] * 4 + [[0, 0, 0]] * 2),
              new_scene_triangles=ns["scene_triangles"], first=0, count=2)
    ns["shader"] = wenv.Shader(ns["env"], ns["mat"], quality="draft")
    run_checked(readme_block(OCCLUDERS), ns, "docs/python.md")
    # after the move, the far point's last texel clears the roof; only the two ground points saw it
    assert ns["occlusion"].visible.shape == (6, 8, 8) and ns["occlusion"].blocked_vertices == 1
    assert ns["occlusion"].cast_vertices == 2
    assert ns["truth"][4, 0] < ns["truth"][5, 0] < 0.5 * 1.01  # (white sky: 0.5 in the open, to the pixels)
    assert ns["rgb"][4, 0] < ns["rgb"][5, 0] and abs(ns["rgb"][4, 0] - ns["truth"][4, 0]) < 0.05
    # the roof's own corners bevel to its normal; the far ground point, with no roof within 0.05, to none
    np.testing.assert_allclose(ns["bevelled"][:4], [[0, 0, 1]] * 4, atol=1e-6)
    assert not ns["bevelled"][5].any()


def test_bent_normals_block_runs():
    """docs/python.md's bent plane under a white sky: the three shares it shows, Cycles' with its Bump
    Map Correction (Blender 4.5's and the earlier releases') and the cosine lobe's above the smooth
    horizon without."""
    ns = {}
    assert run_checked(readme_block(BENT), ns, "docs/python.md") == 3


def test_noise_block_runs():
    """docs/python.md's noise block on a small sphere's vertices: a colour and roughness that vary
    from vertex to vertex, shaded."""
    v, _ = uv_sphere(12, 24)
    n = np.ascontiguousarray(v, np.float32)
    ns = {"wenv": wenv, "points": n, "normals": n, "views": np.tile(np.float32([0, -1, 0.3]), (len(n), 1)),
          "shader": wenv.Shader(wenv.Environment(np.ones((16, 32, 3), np.float32)),
                                wenv.Principled(base_color=(0.5, 0.5, 0.5)), quality="draft")}
    run_checked(readme_block(NOISE), ns, "docs/python.md")
    assert ns["colour"].shape == (len(n), 3) and ns["fac"].std() > 0.02
    assert ns["rgb"].shape == (len(n), 3) and ns["rgb"][:, 0].std() > 0.01


def test_lamps_block_runs():
    """docs/lamps.md's block on a sphere of normals under a dim sky, with its occlusion: the lamps
    brighten the shading, the reference agrees, and the shadowed call is no brighter."""
    v, f = uv_sphere(12, 24)
    n = np.ascontiguousarray(v, np.float32)
    env = wenv.Environment(np.full((16, 32, 3), 0.1, np.float32))
    mat = wenv.Principled(base_color=(0.6, 0.3, 0.2), roughness=0.4)
    ns = {"shader": wenv.Shader(env, mat, quality="draft"), "env": env, "material": mat, "normals": n,
          "views": n.copy(), "positions": n, "eye": (0.0, -4.0, 1.0),
          "occlusion": wenv.Occluders(n, f).occlusion(n, n)}
    plain = ns["shader"].shade(n, n)
    run_checked(readme_block(LAMPS), ns, "docs/lamps.md")
    lit = ns["shader"].shade(n, n, positions=n, lamps=ns["lamps"])
    assert lit.mean() > 2 * plain.mean()
    assert abs(lit.mean() - ns["ref"].mean()) < 0.02 * ns["ref"].mean()
    assert ns["rgb"].shape == n.shape and np.isfinite(ns["rgb"]).all()


def test_sweeps_block_runs(tmp_path, monkeypatch):
    """docs/python.md's sweeps block as written, in a fresh folder: nine readings on this machine's
    pool and again on a two-worker Dask LocalCluster, each written to its results file."""
    monkeypatch.chdir(tmp_path)
    ns = {}
    assert run_checked(readme_block(SWEEPS), ns, "docs/python.md") == 2
    readings = [ns["report"].results[ns["wenv_sweep"].key(job)] for job in ns["jobs"]]
    assert readings == sorted(readings, reverse=True)  # smoother reads higher
    for name in ("sweep.jsonl", "sweep-dask.jsonl"):
        assert len((tmp_path / "out" / name).read_text().splitlines()) == 9


def test_every_python_block_is_run():
    """A Python block added to README.md or a docs/*.md gets a test: these are the blocks run here,
    each in the file it is in, the Blender scripting ones (tests/test_addon.py) and the extension's
    installation (tests/test_addon_install.py runs the same call on the zip it builds)."""
    run = {
        "README.md": [QUICK_START, "import bpy\nbpy.ops.extensions.package_install_files(",
                      "import bpy\nscene = bpy.context.scene"],
        "docs/python.md": [API, OCCLUDERS, BENT, NOISE, SWEEPS],
        "docs/performance.md": [AUTO],
        "docs/principled.md": [PRINCIPLED],
        "docs/measured_brdfs.md": [TABULATED],
        "docs/glossmeter.md": [GLOSSMETER],
        "docs/addon.md": ['import bpy\nmat = bpy.data.materials["paint"]'],
        "docs/lamps.md": [LAMPS],
    }
    found = {}
    for path, text in python_blocks():
        name = path.relative_to(ROOT).as_posix()
        firsts = [first for first in run.get(name, []) if text.startswith(first)]
        assert len(firsts) == 1, f"{name}: a Python block no test runs (or two tests claim): {text[:80]!r}"
        found.setdefault(name, []).extend(firsts)
    assert found == run


def documentation_text(files=None):
    return "\n".join(p.read_text(encoding="utf-8") for p in (files or markdown_files()))


def test_every_name_the_documentation_gives_exists(api_namespace):
    """Every `wenv.<name>` in the text of README.md and docs/*.md is the module's or one of the
    add-on's operators, and every `stats["key"]` they name is in a Shader's stats."""
    text = documentation_text()
    operators_py = ROOT / "addon" / "operators.py"
    operators = re.findall(r'bl_idname = "wenv\.(\w+)"', operators_py.read_text(encoding="utf-8"))
    names = set(re.findall(r"(?<![\w.])wenv\.([A-Za-z_]\w*)", text))
    assert len(names) >= 30 and len(operators) == 10
    assert sorted(n for n in names if not hasattr(wenv, n) and n not in operators) == []
    keys = set(re.findall(r'stats\["(\w+)"\]', text))
    ns = api_namespace
    stats = {**ns["shader"].stats, **wenv.Shader(ns["env"], ns["mat"], quality="auto").stats}
    assert "next_vertex" in keys and sorted(k for k in keys if k not in stats) == []


FENCE = re.compile(r"^ *```.*?^ *```[ \t]*$", re.M | re.S)
LINK = re.compile(r"!?\[[^\]]*\]\(([^()\s]+)\)")


def heading_anchors(path):
    """The anchors GitHub gives the headings of a Markdown file: lower case, punctuation dropped,
    spaces to hyphens, a repeated one numbered."""
    anchors, seen = set(), {}
    for line in FENCE.sub("", path.read_text(encoding="utf-8")).splitlines():
        m = re.match(r"#{1,6} +(.*?) *#*$", line)
        if not m:
            continue
        slug = re.sub(r"[^\w\- ]", "", m.group(1).lower()).replace(" ", "-")
        n = seen.get(slug, 0)
        seen[slug] = n + 1
        anchors.add(slug if n == 0 else f"{slug}-{n}")
    return anchors


def relative_links(path):
    """(target, anchor) of every relative link and image in `path`, code blocks left out."""
    links = []
    for target in LINK.findall(FENCE.sub("", path.read_text(encoding="utf-8"))):
        if re.match(r"[a-z]+:", target):
            continue  # http:, https:, mailto:
        file, _, anchor = target.partition("#")
        links.append((file, anchor))
    return links


def test_the_link_checker_reads_anchors_as_github_does(tmp_path):
    page = tmp_path / "page.md"
    page.write_text("# wenv\n## Peer methods: split-sum and `sh`\n### 3.4 Blender's environments\n"
                    "## Notes\n## Notes\n```sh\n# not a heading\n```\n[a](other.md#x) ![b](pic.png)\n"
                    "[c](#notes-1) [d](https://example.org/x)\n")
    assert heading_anchors(page) == {"wenv", "peer-methods-split-sum-and-sh", "34-blenders-environments",
                                     "notes", "notes-1"}
    assert relative_links(page) == [("other.md", "x"), ("pic.png", ""), ("", "notes-1")]


def test_every_relative_link_resolves():
    """Every relative link and picture in README.md, CHANGELOG.md and docs/*.md points to a file of
    the repository, and an anchor to a heading of the file it names."""
    broken = []
    for path in [*markdown_files(), ROOT / "CHANGELOG.md"]:
        for file, anchor in relative_links(path):
            target = (path.parent / file).resolve() if file else path
            name = f"{path.relative_to(ROOT).as_posix()}: {file}#{anchor}"
            if not target.exists() or ROOT not in target.parents:
                broken.append(name)
            elif anchor and (target.suffix != ".md" or anchor not in heading_anchors(target)):
                broken.append(name)
    assert len(list(ROOT.glob("docs/*.md"))) >= 8
    assert broken == []


def test_no_path_outside_the_repository():
    """The documentation cites papers and the thesis by name, never a file beside the checkout."""
    text = documentation_text([*markdown_files(), ROOT / "CHANGELOG.md"])
    assert re.findall(r"\.\./shared|shared/seed|\.\./\.\./", text) == []


def test_command_blocks_are_the_two_commands_or_name_existing_scripts():
    """The README's first command block is the two commands, and `.ci/run` runs exactly the second;
    every other ```sh or ```bash line of README.md and docs/*.md runs a script of the repository
    (with `bash`, `python` or `.venv/bin/python`) that exists."""
    first = fenced_blocks(conftest.README, ("sh", "bash"))[0][1]
    commands = [line for line in first.splitlines() if line and not line.startswith("#")]
    setup = "bash scripts/setup.sh && "
    assert commands == [setup + ".venv/bin/python examples/demo.py", setup + ".venv/bin/python -m pytest -q tests"]
    ci = [line for line in (ROOT / ".ci" / "run").read_text().splitlines()
          if line and not line.startswith(("#", "set ", "cd "))]
    assert ci == [commands[1]]
    run = 0
    for path in markdown_files():
        for _, block in fenced_blocks(path, ("sh", "bash")):
            for line in block.splitlines():
                line = line.split("  #")[0].strip()
                if not line or line.startswith("#"):
                    continue
                for command in line.split("&&"):
                    words = command.split()
                    assert words[0] in ("bash", "python", ".venv/bin/python"), f"{path.name}: {command}"
                    assert words[1] == "-m" or (ROOT / words[1]).is_file(), f"{path.name}: {command}"
                    run += 1
    assert run >= 20
