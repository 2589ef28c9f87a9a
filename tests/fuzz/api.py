"""Random input to wenv's Python API: odd and bad arguments of every kind (wrong types and shapes,
NaN and infinities, huge and negative numbers, empty and strided arrays, unknown names) to every
public function and method, in random order, on objects made from random input where that succeeded.

What counts as found: an exception other than TypeError, ValueError, OSError or wenv.CancelledError
(and the glossmeter's documented RuntimeError when its integral runs out of evaluations), a
non-finite value returned for finite input, a slow call, or a crash of the
process (the test runs this in a subprocess).  A call is slow when it takes more than --slow
seconds of CPU per thread of wenv's (what it would take on a quiet machine, however busy this one
is) or more than six times that of wall-clock time (a stall that burns no CPU).  Iteration i draws
from its own generator seeded with (seed, i), so a finding is replayed alone with --only i.

    .venv/bin/python tests/fuzz/api.py --seed 0 --iterations 3000 [--json out.json]
    .venv/bin/python tests/fuzz/api.py --seed 0 --only 1234         # replay one iteration, verbosely
"""
import collections
import math
import os
import tempfile
import time
import traceback
import warnings

import numpy as np

import wenv
from draws import Draws, arguments, report

EXPECTED = (TypeError, ValueError, OSError, wenv.CancelledError)
GLOSSMETER_OUT_OF_EVALS = "did not reach tol"


class Found(Exception):
    pass


class Fuzzer(Draws):
    # ---- values ------------------------------------------------------------------------------

    def odd(self, valid, p=0.2):
        """valid, or with probability p something odd (deep paths need mostly valid input)."""
        return self.pick([self.scalar(), self.triple()]) if self.chance(p) else valid

    def scalar(self):
        return self.pick([0, 1, -1, 0.5, 1e-9, 1e-30, 1e30, math.nan, math.inf, -math.inf, 2 ** 63, -2 ** 40, 2 ** 70,
                          True, None, "x", "", b"ab", (), [], {}, 3 + 1j, np.float32(0.3), np.int64(7), 1e-7, 10.0,
                          10.0001, np.array(0.2), np.array([0.1, 0.2])])

    def triple(self):
        return self.pick([(1, 1, 1), (0.5,), (1, 2), (1, 2, 3, 4), (1, 2, 3, 4, 5), [0.2, 0.3, 0.4],
                          np.array([0.1, 0.2, 0.3]), (math.nan, 0, 0), (-1, 0, 0), (1e30, 1, 1), (0, 0, 0), "rgb",
                          (0.2, "x", 0.1), self.scalar()])

    def finite_vectors(self, n):
        return self.r.normal(size=(n, 3)).astype(np.float32)

    def vectors(self):
        """(array, finite): an (n, 3) float32 array of finite values, or something else."""
        n = int(self.pick([0, 1, 2, 3, 7, 100]))
        k = int(self.r.integers(16))
        if k <= 2 or k >= 12:
            return self.finite_vectors(n), True
        if k == 3:
            return self.r.normal(size=(n, 3)).astype(self.pick([np.float64, np.int32, np.float16, np.uint8])), False
        if k == 4:
            return self.r.normal(size=(n, 6)).astype(np.float32)[:, ::2], False  # strided
        if k == 5:
            a = self.finite_vectors(max(n, 1))
            a[self.r.integers(len(a))] = self.pick([np.nan, np.inf, -np.inf])
            return a, False
        if k == 6:
            return self.r.normal(size=self.pick([(n,), (n, 3, 1), (n, 2), (n, 4), (3,), ()])).astype(np.float32), False
        if k == 7:
            return [[1.0, 0.0, 0.0]] * n, False
        if k == 8:
            return np.full((n, 3), self.pick([1e38, -1e38, 0.0, 1e-38]), np.float32), True
        if k == 9:
            return np.ascontiguousarray(self.finite_vectors(n).T), False
        if k == 10:
            a = self.finite_vectors(n)
            a.setflags(write=False)
            return a, True
        return self.scalar(), False

    # ---- objects -----------------------------------------------------------------------------
    def pixels(self):
        if self.chance(0.7):
            h, w = self.pick([(8, 16), (16, 32), (32, 64), (64, 128), (12, 9), (9, 12), (48, 64)])
            a = np.abs(self.r.normal(size=(h, w, 3))).astype(np.float32) * np.float32(self.pick([1.0, 50.0]))
            if self.chance(0.5):  # a sun
                a[self.r.integers(h), self.r.integers(w)] = self.pick([1e3, 1e5, 0.0])
            return a
        h, w = self.pick([(1, 1), (1, 2), (2, 4), (8, 16), (16, 32), (3, 5), (0, 4), (64, 128), (24, 32), (32, 24)])
        a = np.abs(self.r.normal(size=(h, w, int(self.pick([3, 4, 1, 2]))))) * self.pick([1.0, 1e-30, 1e30, 1e6])
        a = a.astype(self.pick([np.float32, np.float32, np.float64]))
        if self.chance(0.15) and a.size:
            a.flat[self.r.integers(a.size)] = self.pick([np.nan, np.inf, -5.0, 1e38])
        if self.chance(0.1):
            a = np.asfortranarray(a)
        if self.chance(0.05):
            a = a[:, ::2]
        return a

    def transform_options(self):
        kw = {}
        if self.chance(0.4):
            kw["rotation"] = self.odd(float(self.r.uniform(-10, 10)))
        if self.chance(0.4):
            kw["strength"] = self.odd(float(self.r.uniform(0, 3)))
        return kw

    def environment(self):
        kw = self.transform_options()
        if self.chance(0.5):
            kw["projection"] = self.odd(self.pick(["equirect", "mirror_ball", "cube_cross"]), 0.3)
        return wenv.Environment(self.pixels(), **kw)

    def lobe(self):
        lobe = {}
        valid = {"alpha": float(self.pick([0.01, 0.05, 0.1, 0.3, 1.0, 1e-6, 10.0])),
                 "specular": self.pick([1.0, (0.9, 0.5, 0.2), 0.0]), "ior": float(self.pick([1.5, 1.01, 10.0, 3.0])),
                 "distribution": self.pick(["ggx", "beckmann"])}
        for key in valid:
            if key == "alpha" or self.chance(0.5):
                lobe[key] = self.odd(valid[key], 0.1)
        if self.chance(0.05):
            lobe["bogus"] = 1
        return lobe

    def material(self):
        k = int(self.pick([0, 1, 1, 1, 2, 2, 3, 4]))
        if k == 0:
            return wenv.Lambert(self.odd(self.pick([0.5, (0.8, 0.2, 0.1), 0.0, 1.0])))
        if k == 1:
            kw = {}
            if self.chance(0.7):
                kw["diffuse"] = self.odd(self.pick([0.2, (0.3, 0.1, 0.05), 0.0]), 0.1)
            if self.chance(0.9):
                kw["lobes"] = self.pick([[self.lobe()], [self.lobe()], [self.lobe(), self.lobe()], [], self.lobe(),
                                         self.scalar()])
            if self.chance(0.3):
                kw["distribution"] = self.odd(self.pick(["ggx", "beckmann"]))
            if self.chance(0.3):
                kw["shadowing"] = self.odd(self.pick(["smith", "vcavity"]))
            return wenv.CookTorrance(**kw)
        if k == 2:
            names = ["base_color", "metallic", "roughness", "ior", "alpha", "specular_ior_level", "specular_tint",
                     "anisotropic", "anisotropic_rotation", "coat_weight", "coat_roughness", "coat_ior", "coat_tint",
                     "sheen_weight", "sheen_roughness", "sheen_tint", "subsurface_weight", "transmission_weight",
                     "diffuse_roughness", "emission_color", "emission_strength", "thin_film_thickness",
                     "thin_film_ior", "bogus", "distribution", "oren_nayar"]
            chosen = self.r.choice(len(names), size=int(self.r.integers(5)), replace=False)
            # finite extremes too: 1e6 is the most an input that scales the reflection may be, 3.4e38 the
            # most a Blender socket holds
            values = [0.0, 0.3, 1.0, (0.8, 0.2, 0.1), 1.45, 500.0, 1e6, 3.4e38, (1e6, 0.5, 2.0)]
            return wenv.Principled(**{names[i]: self.odd(self.pick(values), 0.15) for i in chosen})
        if k == 3:
            shape = self.pick([(2, 2, 2, 3), (1, 1, 1, 3), (4, 3, 2, 3), (2, 2, 3), (0, 2, 2, 3), (3, 3, 4, 1),
                               (8, 8, 8, 3)])
            t = (np.abs(self.r.normal(size=shape)) * self.pick([0.01, 0.3, 1e6])).astype(self.pick([np.float32, np.float64]))
            if self.chance(0.15) and t.size:
                t.flat[self.r.integers(t.size)] = self.pick([np.nan, -1.0, np.inf])
            if self.verbose:
                print(f"table {t.shape} {t.dtype}, largest {t.max() if t.size else None}")
            return wenv.Tabulated(t)
        return wenv.load_brdf(self.file(merl=True))

    def file(self, merl=False):
        """A path to: nothing, a folder, random bytes, a header with a wrong size, or not a path."""
        k = int(self.r.integers(6))
        if k == 0:
            return os.path.join(self.tmp, "missing.bin")
        if k == 1:
            return self.tmp
        if k == 5:
            return self.pick([None, 3, b"\0", "", "\0x"])
        path = os.path.join(self.tmp, "random.bin")
        with open(path, "wb") as f:
            if k == 2:
                f.write(self.r.bytes(int(self.r.integers(0, 300))))
            elif merl:
                dims = np.array(self.pick([(90, 90, 180), (1, 1, 1), (2, 2, 2), (0, 5, 5), (-1, 2, 2), (2 ** 30, 2, 2)]),
                                np.int32)
                f.write(dims.tobytes() + self.r.normal(size=int(self.r.integers(0, 64))).tobytes())
            else:
                f.write(self.pick([b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 2 +X 2\n", b"v/1\x01\x02\x00\x00"]) +
                        self.r.bytes(int(self.r.integers(0, 64))))
        return path

    def quality(self):
        if self.chance(0.5):
            return self.odd(self.pick(["draft", "draft", "draft", "default", "auto"]), 0.1)
        q = {}
        valid = {"global": [32, 64, 16], "local": [8, 16, 32], "normals": [4, 8, 16], "views": [4, 8, 12],
                 "coefficients": [0, 32, 128], "light_coefficients": [0, 64], "matrix_epsilon": [1e-3, 0.0],
                 "lights": [0, 16, 4096], "light_threshold": [8.0, 256.0], "light_tolerance": [0.003, 0.05, 1.0],
                 "grazing": [0.0, 6.0], "grazing_slopes": [0, 1], "lobe_rings": [0, 4, 8]}
        for key, values in valid.items():
            if self.chance(0.3):
                q[key] = self.odd(self.pick(values), 0.1)
        if self.chance(0.05):
            q["bogus"] = 1
        # sizes left out come from `default`: keep the maps small enough that a Shader is quick to make
        q.setdefault("local", 16)
        q.setdefault("normals", 8)
        q.setdefault("views", 8)
        return q

    def shader(self, env, mat):
        kw = {"quality": self.quality(), "cache_dir": False}
        if self.chance(0.5):
            kw["method"] = self.odd(self.pick(["rotation", "slicing", "split_sum", "sh", None]), 0.1)
        if kw["quality"] not in ("draft",) and kw.get("method") in ("rotation", None):
            kw["method"] = self.pick(["slicing", "split_sum", "sh"])  # no multi-second matrix builds
        if self.chance(0.2):
            kw["memory_budget_mb"] = self.pick([0, 1, 64, -1, 1e9, "x", math.nan])
        if self.chance(0.1):
            kw["progress"] = self.pick([None, 3, lambda *a: None, lambda *a: False])
        if kw["quality"] == "auto" and self.chance(0.5):
            kw["target_error"] = self.pick([0.01, 0.0, -1.0, math.nan, 0.5])
        if self.verbose:
            print(f"Shader options: {kw!r}")
        return wenv.Shader(env, mat, **kw)

    # ---- calls -------------------------------------------------------------------------------
    def call(self, name, f, *args, finite=False, **kwargs):
        """Calls f; returns its result or None when it raised what bad input may raise."""
        self.counts["calls"] += 1
        t0, cpu0 = time.perf_counter(), time.process_time()
        try:
            out = f(*args, **kwargs)
        except EXPECTED as e:
            self.counts["raised " + type(e).__name__] += 1
            if self.verbose:
                print(f"{name}: {type(e).__name__}: {e}")
            return None
        except RuntimeError as e:
            if name.startswith("glossmeter") and GLOSSMETER_OUT_OF_EVALS in str(e):
                self.counts["raised RuntimeError (glossmeter evaluations)"] += 1
                return None
            raise Found(f"{name} raised RuntimeError: {e}") from e
        except Exception as e:
            raise Found(f"{name} raised {type(e).__name__}: {e}") from e
        finally:
            wall, cpu = time.perf_counter() - t0, time.process_time() - cpu0
            if cpu > self.slow * wenv.get_num_threads() or wall > 6 * self.slow:
                raise Found(f"{name} took {wall:.1f} s ({cpu:.1f} s of CPU)")
        self.counts["returned " + name] += 1
        if finite:
            for value in (out if isinstance(out, tuple) else (out,)):
                array = np.asarray(value)
                if array.dtype.kind == "f" and not np.all(np.isfinite(array)):
                    raise Found(f"{name} returned non-finite values for finite input")
        if self.verbose:
            print(f"{name}: returned {type(out).__name__}")
        return out

    def shade_calls(self, shader, env, mat):
        for _ in range(int(self.r.integers(1, 9))):
            nrm, nrm_ok = self.vectors()
            view, view_ok = self.pick([self.vectors(), (self.finite_vectors(1)[0], True)])
            k = int(self.r.integers(7))
            if k == 0:
                self.call("Shader.shade", shader.shade, nrm, view, finite=nrm_ok and view_ok)
            elif k == 1:
                kw = {}
                if self.chance(0.5):
                    kw["cull"] = self.pick([True, False, 1, "x"])
                if self.chance(0.3):
                    kw["view_projection"] = self.pick([np.eye(4, dtype=np.float32), np.eye(3), np.full((4, 4), np.nan),
                                                       np.zeros((4, 4)), [[1, 0, 0, 0]] * 4])
                if self.chance(0.3):
                    kw["budget"] = self.pick([0.0, 0.01, -1, math.nan, math.inf, "1"])
                if self.chance(0.3):
                    kw["first"] = self.pick([0, 1, -1, 10 ** 9, 2 ** 70, 0.5, True])
                if self.chance(0.2):
                    rows = np.shape(nrm)[0] if np.ndim(nrm) else 1
                    kw["out"] = self.pick([np.zeros((rows, 3), np.float32),
                                           np.zeros((2, 3), np.float64), np.zeros((3,), np.float32), "x"])
                eye = self.odd(self.pick([(0, 0, 4), (3, -2, 1), (0, 0, 0), (1e30, 0, 0)]))
                finite = nrm_ok and isinstance(eye, tuple) and len(eye) == 3 and all(
                    isinstance(x, (int, float)) and math.isfinite(x) for x in eye)
                self.call("Shader.shade_mesh", shader.shade_mesh, nrm, nrm, eye, finite=finite, **kw)
            elif k == 2:
                other = self.call("Environment", self.environment)
                if other is not None:
                    self.call("Shader.set_environment", shader.set_environment, other)
            elif k == 3:
                other = self.call("material", self.material)
                if other is not None:
                    self.call("Shader.set_material", shader.set_material, other)
            elif k == 4:
                self.call("Shader.set_environment", shader.set_environment, self.pick([mat, None, 3, env]))
            elif k == 5:
                self.call("Shader.stats", lambda: shader.stats)
            else:
                self.call("reference", wenv.reference, env, mat, nrm, view, finite=nrm_ok and view_ok)

    def glossmeter_calls(self, mat):
        if self.chance(0.5):
            self.call("glossmeter gloss", wenv.gloss, mat,
                      self.pick([20, 60, 85, (20, 60), 0, 90, -5, math.nan, "x", 45, (20, "x")]), finite=True)
            return
        kw = {}
        for key in ("angle", "source", "receptor", "receptor_offset", "standard_ior", "normal"):
            if self.chance(0.2):
                kw[key] = self.odd(self.pick([60.0, 20.0, (2.0, 1.0), 0.5, 1.567, (0.1, 0.0, 1.0)]), 0.3)
        meter = self.call("Glossmeter", wenv.Glossmeter, **kw)
        if meter is None:
            return
        opts = {}
        if self.chance(0.3):
            opts["tol"] = self.pick([0.05, 0.0, -1, math.nan, 1e-12, 10.0, "x"])
        if self.chance(0.2):
            opts["max_evals"] = self.pick([1, 0, -1, 10 ** 5, 2 ** 70, 0.5])
        method = self.pick(["measure", "reading", "haze"])
        self.call("glossmeter " + method, getattr(meter, method), mat, finite=True, **opts)

    def environment_calls(self, env):
        dirs, ok = self.vectors()
        k = int(self.r.integers(4))
        if k == 0:
            self.call("Environment.lookup", env.lookup, dirs, finite=ok)
        elif k == 1:
            self.call("Environment.with_transform", env.with_transform, **self.transform_options())
        elif k == 2:
            self.call("Environment.samples", env.samples, finite=True)
        else:
            self.call("Environment.solid_angles", env.solid_angles, finite=True)

    def material_calls(self, mat):
        wi, wi_ok = self.vectors()
        wo, wo_ok = self.vectors()
        if self.chance(0.5):
            self.call("Material.eval", mat.eval, wi, wo, finite=wi_ok and wo_ok)
        else:
            samples = self.pick([[], [self.pick([8, 0, 7, 5000, -1, "x", 16.5])]])
            self.call("Material.albedo", mat.albedo, wo, *samples, finite=wo_ok)

    def iteration(self):
        k = int(self.r.integers(10))
        if k == 0:
            self.call("load_environment", wenv.load_environment, self.file(), **self.transform_options())
            return
        if k == 1:
            pos, ok = self.vectors()
            eye = self.pick([(0, 0, 4), (math.nan, 0, 0), self.triple()])
            self.call("visible_vertices", wenv.visible_vertices, pos, pos, eye)
            self.call("alpha_from_roughness", wenv.alpha_from_roughness, self.scalar())
            return
        env = self.call("Environment", self.environment)
        mat = self.call("material", self.material)
        if env is not None and self.chance(0.3):
            self.environment_calls(env)
        if mat is not None and self.chance(0.3):
            self.material_calls(mat)
        if mat is not None and self.chance(0.08):
            self.glossmeter_calls(mat)
        if env is None or mat is None:
            return
        shader = self.call("Shader", self.shader, env, mat)
        if shader is not None:
            self.shade_calls(shader, env, mat)


def run(seed, iterations, only=None, slow=10.0, verbose=False):
    """Runs the iterations; returns (summary dict, finding or None)."""
    warnings.simplefilter("ignore")  # RuntimeWarnings for tables that reflect more than they receive
    counts = collections.Counter()
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        for i in ([only] if only is not None else range(iterations)):
            fuzzer = Fuzzer(np.random.default_rng([seed, i]), tmp, slow, verbose)
            try:
                fuzzer.iteration()
            except Found as e:
                detail = "".join(traceback.format_exception(e.__cause__)) if e.__cause__ else ""
                return ({"iterations": i, "seconds": time.perf_counter() - t0, "counts": dict(counts + fuzzer.counts)},
                        {"iteration": i, "seed": seed, "what": str(e), "traceback": detail})
            counts += fuzzer.counts
    n = 1 if only is not None else iterations
    return {"iterations": n, "seconds": time.perf_counter() - t0, "counts": dict(counts)}, None


def main():
    args = arguments(__doc__, 3000, 10.0, "a call taking more than this many seconds of CPU per thread (or six "
                     "times it of wall-clock time) is a finding")
    wenv.set_num_threads(2)
    report(args, *run(args.seed, args.iterations, args.only, args.slow, verbose=args.only is not None))


if __name__ == "__main__":
    main()
