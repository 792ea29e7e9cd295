"""petsc-htp bench: a quick end-to-end run through real PETSc, report regeneration, README, failures."""
import json
import os
import re
import shutil
from pathlib import Path

import numpy as np
import pytest

import petsc4py  # noqa: F401,E402  (missing components fail, never skip)
import pyamg  # noqa: F401,E402

from petsc_htp.training import checkpoint  # noqa: E402
from petsc_htp.bench import aggregate, main, store  # noqa: E402
from petsc_htp.bench.methods import DEFAULT_METHODS, resolve_method  # noqa: E402
from petsc_htp.bench.readme import END, START  # noqa: E402
from petsc_htp.bench.studies import STUDIES  # noqa: E402
from petsc_htp.bench.studies.base import Size, Study  # noqa: E402
from petsc_htp.bench.studies.simulation import RATIO_BAR, is_htp, is_twolevel, ratios  # noqa: E402
from petsc_htp.bench.studies.stability import STRESS, boundary, natural_order, over_budget, sealed  # noqa: E402
from petsc_htp.paper.model import HTPConfig, HTPNet  # noqa: E402
from petsc_htp.scenes.generator import make_frame  # noqa: E402

QUICK_PNGS = ("table4.png", "sequence.png", "scaling.png", "curves_n256.png", "curves_n512.png",
              "curves_summary.png", "stability.png")
CLASSICAL = ("cg_none", "cg_jacobi", "cg_icc", "cg_bjacobi", "cg_gamg", "pyamg")


@pytest.fixture(scope="module")
def env(tmp_path_factory):
    """A private frame cache and a tiny untrained checkpoint."""
    import torch

    base = tmp_path_factory.mktemp("bench")
    old = os.environ.get("PETSC_HTP_CACHE")
    os.environ["PETSC_HTP_CACHE"] = str(base / "cache")
    torch.manual_seed(0)
    ckpt = checkpoint.save(base / "tiny.pt", HTPNet(HTPConfig(d=32, n_layers=1, heads=4)), {"note": "test"})
    yield {"base": base, "ckpt": str(ckpt), "common": ["--checkpoint", str(ckpt), "--threads", "1", "--no-progress"]}
    if old is None:
        os.environ.pop("PETSC_HTP_CACHE", None)
    else:
        os.environ["PETSC_HTP_CACHE"] = old


@pytest.fixture(scope="module")
def quick(env):
    """One ``bench --quick`` run with the default methods and studies (about 10 s; its tests are slow)."""
    out = env["base"] / "quick"
    assert main(["--quick", "--out", str(out), *env["common"]]) == 0
    return out


def rows_of(out, study):
    return store.read_jsonl(store.study_path(out, study))


def by_method(rows):
    return {m: [r for r in rows if r["method"] == m] for m in dict.fromkeys(r["method"] for r in rows)}


# ------------------------------------------------------------------ quick run

@pytest.mark.slow
def test_quick_run_writes_every_artefact(quick):
    for study in ("table", "sequence", "curves", "stability"):
        assert rows_of(quick, study), study
    for name in QUICK_PNGS:
        data = (quick / name).read_bytes()
        assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 2000, name
    report = (quick / "report.md").read_text()
    for heading in ("## 1. Time per frame", "## Sequence mode", "## 2. Speed against accuracy",
                    "## 3. Time against N", "## 4. Stability map"):
        assert heading in report
    assert "## 5." not in report and "## 8." not in report
    for name in QUICK_PNGS:
        assert f"]({name})" in report
    meta = json.loads((quick / "meta.json").read_text())
    assert meta["quick"] and meta["methods"] == list(DEFAULT_METHODS)
    assert meta["machine"]["cpu"] and meta["date"] and meta["versions"]["PETSc"].startswith("3.")
    assert meta["threads"]["torch"] == 1
    assert set(meta["study_s"]) == {"table", "sequence", "curves", "scaling", "stability"}
    assert not list(quick.glob(".*.tmp"))


@pytest.mark.slow
def test_quick_table_rows_measure_every_method(quick):
    rows = rows_of(quick, "table")
    methods = by_method(rows)
    assert list(methods) == list(DEFAULT_METHODS)
    for m, got in methods.items():
        assert sorted((r["n"], r["seed"]) for r in got) == [(256, 1_000_000), (256, 1_000_001),
                                                             (512, 1_000_000), (512, 1_000_001)], m
    for m in CLASSICAL:
        for r in methods[m]:
            assert r["ok"] and r["reason"].startswith("CONVERGED"), r
            assert r["relres_proj"] <= 1e-7
            assert r["total_ms"] == pytest.approx(r["setup_ms"] + r["solve_ms"])
    its = {m: np.mean([r["iterations"] for r in methods[m] if r["n"] == 512]) for m in CLASSICAL}
    assert its["pyamg"] < its["cg_icc"] < its["cg_jacobi"] <= its["cg_none"]
    assert {r["pc"] for r in methods["cg_bjacobi"]} == {"bjacobi"}
    assert all(r["ok"] == (r["failure"] is None) for r in rows)
    none = {(r["n"], r["seed"]): r["iterations"] for r in methods["cg_none"]}
    for r in methods["cg_paper"]:       # the tiny untrained network starts out close to Jacobi
        assert r["ok"] and r["reason"].startswith("CONVERGED") and r["relres_proj"] <= 1e-7, r
        assert r["pc"] == "python"
        assert r["iterations"] < none[(r["n"], r["seed"])]


@pytest.mark.slow
def test_table4_text_matches_rows(quick):
    report = (quick / "report.md").read_text()
    rows = [r for r in rows_of(quick, "table") if r["method"] == "cg_jacobi" and r["n"] == 512]
    mean_ms = np.mean([r["total_ms"] for r in rows])
    mean_its = np.mean([r["iterations"] for r in rows])
    line = next(li for li in report.splitlines() if li.startswith("| cg_jacobi |"))
    shown = f"{mean_ms:.2f}" if mean_ms < 10 else f"{mean_ms:.1f}"     # two decimals below 10 ms, else one
    assert f"{shown} ({mean_its:,.0f})" in line


@pytest.mark.slow
def test_curves_reach_the_tolerance(quick):
    rows = [r for r in rows_of(quick, "curves") if r["method"] in CLASSICAL]
    assert {r["method"] for r in rows} == set(CLASSICAL)
    for r in rows:
        assert r["ok"], r
        t, it, rel = np.array(r["curve"]).T
        assert np.all(np.diff(t) >= 0) and it[0] == 0 and it[-1] == r["iterations"], r["method"]
        assert rel[-1] <= 1e-8 and aggregate.time_to(r["curve"], 1e-3) <= aggregate.time_to(r["curve"], 1e-8)


@pytest.mark.slow
def test_stability_covers_every_case(quick):
    rows = rows_of(quick, "stability")
    assert {(r["case"], r["method"]) for r in rows} == {(c, m) for c, _ in STRESS for m in DEFAULT_METHODS}
    jac = {r["case"]: r for r in rows if r["method"] == "cg_jacobi"}
    assert jac["large N"]["n"] == 2048 and jac["odd N"]["n"] == 300 and jac["huge N"]["n"] == 4096
    assert jac["rtol 1e-14"]["rtol"] == 1e-14 and jac["simulation"]["n"] < 256
    assert jac["rtol 1e-10"]["rtol"] == 1e-10 and jac["rtol 1e-10"]["relres_proj"] <= 1e-9
    assert jac["natural order"]["ok"] and jac["reference"]["ok"]
    assert jac["inconsistent rhs"]["relres"] > 0.05      # the constant part of b can never be matched
    report = (quick / "report.md").read_text()
    for case, _ in STRESS:
        assert f"| {case} |" in report


@pytest.mark.slow
def test_report_only_reproduces_the_report(quick, tmp_path):
    copy = tmp_path / "copy"
    shutil.copytree(quick, copy)
    for png in copy.glob("*.png"):
        png.unlink()
    (copy / "report.md").unlink()
    assert main(["--report-only", str(copy)]) == 0
    assert (copy / "report.md").read_text() == (quick / "report.md").read_text()
    for name in QUICK_PNGS:
        assert (copy / name).stat().st_size > 2000


@pytest.mark.slow
def test_readme_block_rewrite(quick, tmp_path, capsys):
    readme = tmp_path / "README.md"
    head, tail = "# project\n\nintro\n\n## Results\n\n", "\n\n## Licence\n\nBSD\n"
    readme.write_text(f"{head}{START}\nold text\n{END}{tail}")
    assert main(["--readme", str(quick), "--readme-file", str(readme)]) == 0
    text = readme.read_text()
    assert text.startswith(head + START) and text.endswith(END + tail) and "old text" not in text
    block = text[text.index(START):text.index(END)]
    rel = os.path.relpath(quick, tmp_path)
    assert f"({rel}/report.md)" in block and f"({rel}/table4.png)" in block and f"({rel}/scaling.png)" in block
    meta = json.loads((quick / "meta.json").read_text())
    assert meta["date"] in block and meta["machine"]["cpu"] in block
    for m in DEFAULT_METHODS:
        assert f"| {m} |" in block
    assert main(["--readme", str(quick), "--readme-file", str(readme)]) == 0
    assert readme.read_text() == text
    bare = tmp_path / "BARE.md"
    bare.write_text("# no markers\n")
    capsys.readouterr()
    assert main(["--readme", str(quick), "--readme-file", str(bare)]) == 2
    err = capsys.readouterr().err
    assert START in err and END in err and bare.read_text() == "# no markers\n"


# ------------------------------------------------------------------ failures

def test_failing_methods_become_failure_rows(env, tmp_path):
    bad = tmp_path / "broken_pc.opts"
    bad.write_text("-options_file options/common.opts\n-ksp_type cg\n-pc_type python\n"
                   "-pc_python_type nonexistent.Module\n")
    short = tmp_path / "two_its.opts"
    short.write_text("-options_file options/common.opts\n-ksp_type cg\n-pc_type jacobi\n-ksp_max_it 2\n")
    out = tmp_path / "fail"
    argv = ["--quick", "--out", str(out), "--methods", str(bad), "cg_jacobi", str(short),
            "--studies", "table", "stability", "--scales", "256", "--frames", "1",
            "--frame-budget-ms", "1e9", *env["common"]]          # no budget: failures are the solver's own
    assert main(argv) == 0
    rows = by_method(rows_of(out, "table"))
    assert [r["failure"] for r in rows["broken_pc"]] == ["EXCEPTION"]
    assert "nonexistent" in rows["broken_pc"][0]["error"]
    assert rows["two_its"][0]["failure"] == "DIVERGED_ITS" and rows["two_its"][0]["iterations"] == 2
    assert rows["cg_jacobi"][0]["ok"]
    stab = by_method(rows_of(out, "stability"))
    assert len(stab["broken_pc"]) == len(STRESS) and not any(r["ok"] for r in stab["broken_pc"])
    hard = {"inconsistent rhs", "contrast 1e8"}      # Jacobi's boundary: indefinite in floating point
    assert all(r["ok"] for r in stab["cg_jacobi"] if r["case"] not in hard)
    report = (out / "report.md").read_text()
    assert "| broken_pc | ✗ exception |" in report and "| two_its | ✗ max it |" in report
    assert "Failures:" in report


def test_bare_study_solves_the_dirichlet_problem_with_every_method(env, tmp_path):
    out = tmp_path / "bare"
    assert main(["--quick", "--out", str(out), "--studies", "bare", "--methods", "cg_icc", "cg_gamg", "cg_htp",
                 "pyamg", *env["common"]]) == 0
    rows = by_method(rows_of(out, "bare"))
    for m, got in rows.items():                      # nonsingular: b is not projected, x = 0 is no answer
        assert [r["n"] for r in got] == [32 * 32] and got[0]["ok"] and got[0]["relres"] <= 1e-8, got
    assert rows["cg_htp"][0]["iterations"] < rows["cg_icc"][0]["iterations"]
    assert rows["pyamg"][0]["iterations"] > 0
    assert "## A bare single solve" in (out / "report.md").read_text()


def test_unknown_method_is_a_usage_error(env, tmp_path, capsys):
    assert main(["--quick", "--out", str(tmp_path / "x"), "--methods", "cg_nothing"]) == 2
    assert "cg_nothing" in capsys.readouterr().err


# ------------------------------------------------------------------ registry

class Echo(Study):
    """A study registered from outside: one row per method, a section, a chart and a README link."""

    name = "echo"
    help = "test study"
    sizes = (Size("echo_n", 64, 32, "N of the echo study"),)
    readme_links = (("echo.png", "echo chart"),)

    def meta(self, settings):
        return {"echo": settings["echo_n"]}

    def expected_solves(self, ctx):
        return len(ctx.methods)

    def measure(self, ctx, tick):
        rows = []
        for i, m in enumerate(ctx.methods):
            rows.append({"method": m.name, "n": ctx.settings["echo_n"], "ok": True, "total_ms": 1.0, "iterations": i})
            tick()
        return rows

    def section(self, res):
        by = aggregate.cells(res.rows["echo"], "method", "n")
        return "## 9. Echo\n\n" + ", ".join(f"{m}: {c['iterations']['mean']:.0f}" for (m, _), c in by.items())

    def charts(self, res, out):
        with open(os.path.join(out, "echo.png"), "wb") as fh:
            fh.write(b"png")
        return ["echo.png"]


def test_a_registered_study_reaches_flags_meta_report_and_readme(env, tmp_path, monkeypatch):
    monkeypatch.setitem(STUDIES, "echo", Echo())
    out = tmp_path / "echo"
    assert main(["--quick", "--out", str(out), "--studies", "echo", "--echo-n", "48", "--methods", "cg_jacobi",
                 "pyamg", *env["common"]]) == 0
    assert [(r["method"], r["n"]) for r in rows_of(out, "echo")] == [("cg_jacobi", 48), ("pyamg", 48)]
    meta = json.loads((out / "meta.json").read_text())
    assert meta["echo"] == 48 and meta["studies"] == ["echo"]
    report = (out / "report.md").read_text()
    assert report.endswith("## 9. Echo\n\ncg_jacobi: 0, pyamg: 1\n") and "## 1." not in report
    readme = tmp_path / "README.md"
    readme.write_text(f"{START}\n{END}\n")
    assert main(["--readme", str(out), "--readme-file", str(readme)]) == 0
    assert "More charts: [echo chart](echo/echo.png)." in readme.read_text()


def test_registry_is_consistent():
    assert list(STUDIES) == [s.name for s in STUDIES.values()]
    assert all(STUDIES[s.data].data == s.data for s in STUDIES.values())   # data studies measure themselves
    charts = [name for s in STUDIES.values() for name, _ in s.readme_links]
    assert len(charts) == len(set(charts)) and all(s.help for s in STUDIES.values())


# ------------------------------------------------------------------ pieces

def test_options_loader_follows_includes_and_sets_bjacobi_blocks(tmp_path, monkeypatch):
    from petsc4py import PETSc

    from petsc_htp.bench.runner import load
    from petsc_htp.bench.harness import Loaded, bjacobi_blocks

    monkeypatch.chdir(tmp_path)                      # includes resolve from any working directory
    with Loaded("cg_jacobi", prefix="t_jac_"):
        db = PETSc.Options("t_jac_")
        assert db.getReal("ksp_rtol") == 1e-8 and db.getString("pc_type") == "jacobi"
    assert not PETSc.Options("t_jac_").hasName("pc_type")
    method = resolve_method("cg_bjacobi")
    loaded = load(method)
    try:
        db = PETSc.Options(method.prefix)
        for n, blocks in ((1000, 8), (300, 3)):
            with bjacobi_blocks(method.prefix, n) as count:
                assert count == blocks and db.getInt("pc_bjacobi_blocks") == blocks
            assert not db.hasName("pc_bjacobi_blocks")       # nothing left behind
        db.setValue("pc_bjacobi_blocks", 5)
        with bjacobi_blocks(method.prefix, 1000) as count:
            assert count == 5                                # the user's count wins
        assert db.getInt("pc_bjacobi_blocks") == 5 and db.getString("sub_pc_type") == "cholesky"
        db.delValue("pc_bjacobi_blocks")
        assert not db.hasName("ksp_converged_reason")
    finally:
        loaded.__exit__(None, None, None)
    assert not PETSc.Options(method.prefix).hasName("pc_type")
    assert not PETSc.Options(method.prefix).hasName("pc_bjacobi_blocks")


def test_natural_order_is_the_same_system():
    frame = make_frame(300, seed=3)
    nat = natural_order(frame)
    order = np.argsort(frame.perm)
    assert np.all(np.diff(nat.perm) > 0)
    np.testing.assert_allclose(nat.A.toarray(), frame.A.toarray()[np.ix_(order, order)])
    np.testing.assert_allclose(nat.b, frame.b[order])


def test_aggregate_helpers():
    assert aggregate.scaling_exponent([1024, 2048, 4096], [1.0, 4.0, 16.0]) == pytest.approx(2.0)
    assert aggregate.largest_within([1, 2, 3], [5.0, 20.0, 50.0], 41.7) == 2
    assert aggregate.pareto_front([(1, 5), (2, 3), (3, 4), (4, 1)]) == [0, 1, 3]
    assert aggregate.time_to([[1.0, 0, 1.0], [2.0, 1, 1e-4], [3.0, 2, 1e-9]], 1e-3) == 2.0
    assert aggregate.time_to([[1.0, 0, 1.0]], 1e-3) is None


# ---------------------------------------------------------- trained-model studies

@pytest.mark.slow
def test_trained_model_studies(env, tmp_path):
    """One real tiny training run feeds the generalization, size and profile studies and their report."""
    from petsc_htp.bench import cli, training
    from petsc_htp.bench.report import load
    from petsc_htp.bench.runner import htp_options
    from petsc_htp.bench.studies import generalization, profile, size

    budget = training.Budget(minutes=0.5, steps=2, scales=(256,), frames=2, eval_n=256, log_every=1, eval_every=1)
    cfg = HTPConfig(d=32, n_layers=1, heads=4)
    path = training.trained_checkpoint(tmp_path, cfg, "full", "cosine", budget)
    stamp = path.stat().st_mtime_ns
    assert training.trained_checkpoint(tmp_path, cfg, "full", "cosine", budget) == path
    assert path.stat().st_mtime_ns == stamp                      # same budget: reused, not retrained
    info = training.model_info(path)
    assert info["train_steps"] == 2 and info["d"] == 32 and info["params"] == HTPNet(cfg).n_params()
    wide = HTPConfig(d=64, n_layers=1, heads=4, highways=False)
    other = checkpoint.save(tmp_path / "wide.pt", HTPNet(wide), {"loss": "sai", "steps": 0, "wall_s": 0.0})

    out = tmp_path / "res"
    extra, tick = htp_options(threads=1), lambda: None
    rows = {"generalization": generalization.run({"full": path, "no_closed": other}, 256, 1, extra, tick),
            "size": size.run([(cfg, "cosine", path), (wide, "sai", other)], cfg, [256], 1, extra, tick),
            "profile": profile.run(path.parent / "train_log.jsonl", path, 256)}
    for study, got in rows.items():
        store.write_jsonl(store.study_path(out, study), got)
    store.write_json(out / "meta.json", {"studies": list(rows), "budget": {"text": budget.describe()},
                                         "generalization": {"n": 256, "frames": 1}, "size": {"frames": 1}})
    cli.finish(out)

    gen = rows["generalization"]
    assert len(gen) == 4 * (3 + len(generalization.VARIANTS))
    assert {r["train"] for r in gen} == {None, "full", "no_closed"}
    assert all(r["ok"] for r in gen if r["method"] == "cg_jacobi" or r.get("variant"))
    assert {r["variant"] for r in gen if r.get("variant")} == set(generalization.VARIANTS)
    assert {r["config"]: r["params"] for r in rows["size"]} == {
        "d=32, n_l=1, hw, cosine": HTPNet(cfg).n_params(), "d=64, n_l=1, no-hw, sai": HTPNet(wide).n_params()}
    prof = aggregate.group(rows["profile"], "kind")
    assert [r["step"] for r in prof[("train",)]][:2] == [1, 2] and len(prof[("baseline",)]) == 2
    spec = {r["method"]: r for r in prof[("spectrum",)]}
    assert set(spec) == {"none", "jacobi", "htp", *profile.VARIANTS} and len(spec["none"]["eigs"]) == 255
    assert spec["jacobi"]["kappa"] < spec["none"]["kappa"]
    assert all(not spec[v]["indefinite"] and spec[v]["kappa"] < spec["jacobi"]["kappa"] / 10 for v in profile.VARIANTS)

    report = (out / "report.md").read_text()
    for heading in ("## 5. Generalization", "## 6. Model size", "## 7. Training profile"):
        assert heading in report
    assert "at most 2 steps and 0.5 min per model" in report
    assert "| Full / in-distribution |" in report and "| Excl. closed barriers |" in report
    assert "| cg_twolevel_eig |" in report and "Two-level variants on the same frames" in report
    assert "Smallest configuration within 10% of the fastest" in report
    para = STUDIES["size"].readme(load(out), "")
    assert "**Model size**" in para and "`d=32, n_l=1, hw, cosine`" in para and "at most 2 steps" in para
    for name in ("generalization.png", "size.png", "profile.png", "spectrum.png"):
        assert (out / name).stat().st_size > 2000

    cli_out = tmp_path / "cli"
    assert main(["--quick", "--out", str(cli_out), "--studies", "profile", "--train-log",
                 str(path.parent / "train_log.jsonl"), *env["common"]]) == 0
    assert "## 7. Training profile" in (cli_out / "report.md").read_text()


@pytest.mark.slow
def test_rank_study_sweeps_eig_against_learned(env, tmp_path):
    out = tmp_path / "rank"
    assert main(["--quick", "--out", str(out), "--studies", "rank", "--ranks", "1", "2", *env["common"]]) == 0
    rows = rows_of(out, "rank")
    assert {r["method"] for r in rows} == {"eig_r1", "eig_r2", "cg_twolevel_learned"}
    assert all(r["ok"] for r in rows)
    by = aggregate.cells(rows, "method")
    assert by[("eig_r2",)]["iterations"]["mean"] <= by[("eig_r1",)]["iterations"]["mean"]
    assert by[("eig_r2",)]["bytes_per_unknown"]["median"] > by[("eig_r1",)]["bytes_per_unknown"]["median"]
    report = (out / "report.md").read_text()
    assert "## Coarse-space size (two-level variant)" in report and "| eig | 2 |" in report
    assert re.search(r"learned \(r = 4\) \d+ its, eig reaches it (at r = \d|at no r ≤ 2)", report)


def test_fastpath_study_runs_on_this_machine(env, tmp_path):
    import torch

    out = tmp_path / "fast"
    assert main(["--quick", "--out", str(out), "--studies", "fastpath", "--scales", "1024", "--frames", "1",
                 *env["common"]]) == 0
    rows = rows_of(out, "fastpath")
    assert [r["method"] for r in rows] == ["none", "jacobi", "bjacobi", "htp", "twolevel_const", "twolevel_eig",
                                          "twolevel_learned"]
    assert all(r["n"] == 1024 for r in rows)
    assert all(r["ok"] for r in rows if r["method"] != "htp")
    its = {r["method"]: r["iterations"] for r in rows}
    assert its["twolevel_eig"] < its["bjacobi"] < its["jacobi"] and its["twolevel_learned"] < its["bjacobi"]
    report = (out / "report.md").read_text()
    assert "## 8. Fast path" in report and (out / "fastpath.png").stat().st_size > 2000
    if not torch.cuda.is_available():
        assert rows[0]["device"] == "cpu" and "ran eagerly" in report


def test_model_card_lists_training_stages_oldest_first():
    from petsc_htp.bench.modelcard import training_stages

    prov = {"steps": 10, "scales": [2048], "init": {"steps": 500, "scales": [1024], "init": {"steps": 2608}}}
    assert [st["steps"] for st in training_stages(prov)] == [2608, 500, 10]
    assert training_stages({"steps": 3}) == [{"steps": 3}]


# ------------------------------------------------------------------ simulation and stability limits

def test_simulation_study_measures_reuse_and_the_iteration_ratio(env, tmp_path):
    out = tmp_path / "sim"
    argv = ["--quick", "--studies", "simulation", "--methods", "cg_jacobi", "cg_paper", "cg_twolevel_const",
            "--out", str(out), *env["common"]]
    assert main(argv) == 0
    rows = rows_of(out, "simulation")
    sim = [r for r in rows if r["kind"] == "simulation"]
    runs = {(r["method"], r["reuse"], r["keep"]) for r in sim}
    assert runs == {("cg_jacobi", 0, 0), ("cg_paper", 0, 0), ("cg_paper", 2, 0), ("cg_twolevel_const", 0, 0),
                    ("cg_twolevel_const", 2, 0), ("cg_twolevel_const", 0, 2)}
    for method, reuse, keep in runs:
        got = [r for r in sim if (r["method"], r["reuse"], r["keep"]) == (method, reuse, keep)]
        assert [r["frame"] for r in got] == [0, 1, 2, 3] and all(r["ok"] for r in got), got
        assert [r["rebuilt"] for r in got] == ([True] * 4 if reuse == 0 else [True, False, True, False])
        if method != "cg_jacobi":        # the python PC's own count of numeric setups agrees
            assert [r["numeric_setups"] for r in got] == [int(r["rebuilt"]) for r in got]
    assert "cg_twolevel_const keep W 2" in (out / "report.md").read_text()
    gen = [r for r in rows if r["kind"] == "generator"]
    assert {r["method"] for r in gen} == {"cg_jacobi", "cg_paper", "cg_twolevel_const"}
    assert all(r["n"] == 32 * 32 and r["ok"] for r in gen)
    report = (out / "report.md").read_text()
    assert "## 9. Simulation" in report and "](simulation.png)" in report
    assert (out / "simulation.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    from petsc_htp.bench.report import load
    for side, method, htp, s, g, r in ratios(load(out)):
        sim_its = np.mean([x["iterations"] for x in sim if (x["method"], x["reuse"]) == (method, 0)])
        gen_its = np.mean([x["iterations"] for x in gen if x["method"] == method])
        assert r == pytest.approx(sim_its / gen_its) and htp == (method != "cg_jacobi")
        line = next(li for li in report.splitlines()
                    if li.startswith(f"| {method}" + (" (HTP)" if htp else " |")) and f"| {side}² |" in li)
        verdict = ("✓" if r <= RATIO_BAR else "✗") if htp else ""
        assert f"| {r:.2f}× | {verdict} |" in line


def test_htp_variants_are_found_from_the_options():
    htp = {"cg_htp", "cg_paper", "cg_twolevel_const", "cg_twolevel_eig", "gmres_paper", "gmres_twolevel",
           "bjacobi_paper"}
    for name in htp | {"cg_none", "cg_jacobi", "cg_icc", "cg_bjacobi", "cg_gamg"}:
        assert is_htp(resolve_method(name)) == (name in htp), name
    assert not is_htp(resolve_method("pyamg"))
    twolevel = {"cg_htp", "cg_twolevel_const", "cg_twolevel_eig", "cg_twolevel_learned", "gmres_twolevel"}
    for name in htp | twolevel | {"cg_icc", "cg_gamg"}:
        assert is_twolevel(resolve_method(name)) == (name in twolevel), name


def test_new_stress_cases_exist():
    names = [c for c, _ in STRESS]
    for case in ("contrast 1e6", "contrast 1e8", "rtol 1e-14", "regions", "huge N", "simulation"):
        assert case in names
    sizes = {s.name: s for s in STUDIES["stability"].sizes}
    assert sizes["huge_n"].full == 262144 and sizes["huge_n"].quick < 262144
    assert sizes["frame_budget_ms"].full == pytest.approx(1e3 / 24, abs=0.05)


def test_sealed_regions_carry_one_null_vector_each():
    from petsc4py import PETSc

    from petsc_htp.petscmat import frame_mat

    frame = sealed(make_frame(1024, seed=1_000_002, distribution="closed_only"))
    regions = frame.params["regions"]
    assert regions >= 2
    mat = frame_mat(frame, PETSc.COMM_SELF)
    vecs = mat.getNullSpace().getVecs()
    assert len(vecs) == regions
    for v in vecs:
        null = v.getArray(readonly=True)
        assert np.abs(frame.A @ null).max() < 1e-9 and abs(null @ frame.b) < 1e-9
    assert np.abs(frame.A @ np.ones(frame.n)).max() < 1e-9
    mat.destroy()


def test_budget_marks_slow_frames_failed():
    rows = [{"ok": True, "failure": None, "total_ms": 50.0, "case": "a", "method": "slow"},
            {"ok": True, "failure": None, "total_ms": 10.0, "case": "a", "method": "fast"},
            {"ok": False, "failure": "DIVERGED_ITS", "total_ms": 90.0, "case": "b", "method": "fast"}]
    over_budget(rows, 41.7)
    assert [(r["ok"], r["failure"]) for r in rows] == [(False, "BUDGET"), (True, None), (False, "DIVERGED_ITS")]
    assert boundary(rows, ["slow", "fast"], ["a", "b"]) == {"slow": "a", "fast": "b"}


def test_methods_take_turns_frame_by_frame(env):
    """run_methods solves each frame with every method before the next frame (drift hits all alike)."""
    from petsc_htp.bench.cases import table_problems
    from petsc_htp.bench.methods import resolve_methods
    from petsc_htp.bench.runner import run_methods

    methods = resolve_methods(["cg_jacobi", "cg_icc"])
    rows = run_methods(methods, table_problems([256], 2), warmup=False)
    assert [(r["method"], r["seed"]) for r in rows] == [(m, s) for s in sorted({r["seed"] for r in rows})
                                                        for m in ("cg_jacobi", "cg_icc")]
    assert all(r["ok"] for r in rows)


def test_repeated_single_solves_keep_the_median_row(env):
    """With ``repeats`` each method solves a problem that many times in a row; the row of the median total time is
    kept, a failed solve wins over the median."""
    from petsc_htp.bench.cases import table_problems
    from petsc_htp.bench.methods import resolve_methods
    from petsc_htp.bench.runner import _median, run_methods

    rows = run_methods(resolve_methods(["cg_jacobi", "cg_icc"]), table_problems([256], 1), warmup=False,
                       repeats=lambda problem: 3)
    assert [(r["method"], r["repeats"], r["ok"]) for r in rows] == [("cg_jacobi", 3, True), ("cg_icc", 3, True)]
    made = [{"ok": True, "total_ms": t} for t in (3.0, 1.0, 2.0)]
    assert _median(made)["total_ms"] == 2.0 and _median(made)["repeats"] == 3
    assert _median(made + [{"ok": False, "total_ms": None}])["ok"] is False
    assert "repeats" not in _median(made[:1])


def test_gamg_sweep_points_load_the_default_file_with_threshold_and_aggressive_levels_set():
    """``gamg_t<threshold>_a<levels>`` is cg_gamg_default.opts with the two GAMG knobs set under its own prefix;
    the families and their defaults are read off the names."""
    from petsc4py import PETSc

    from petsc_htp.bench.methods import family, resolve_method
    from petsc_htp.bench.runner import load

    m = resolve_method("gamg_t0.05_a0")
    assert m.path.name == "cg_gamg_default.opts" and m.prefix == "bench_gamg_t0_05_a0_"
    loaded = load(m)
    try:
        db = PETSc.Options(m.prefix)
        assert db.getString("pc_type") == "gamg" and db.getReal("pc_gamg_threshold") == 0.05
        assert db.getInt("pc_gamg_aggressive_coarsening") == 0
    finally:
        loaded.__exit__(None, None, None)
    assert not PETSc.Options(m.prefix).hasName("pc_gamg_threshold")
    assert [family(n) for n in ("cg_gamg", "gamg_t0_a1", "amgcl_ce500", "pyamg_sa", "cg_htp")] == [
        ("GAMG", "cg_gamg_default"), ("GAMG", "cg_gamg_default"), ("AMGCL", "amgcl"), ("pyamg", "pyamg"), None]
    with pytest.raises(ValueError, match="unknown method"):
        resolve_method("gamg_tx_a1")


@pytest.mark.slow
def test_scale_study_runs_the_dmda_program_on_one_and_two_ranks(env, tmp_path):
    """The scale study: one mpiexec process per method, grid and rank count (bench/dmdarun.py), a single solve and a
    sequence frame each, AMGCL on one rank only (and refused by name on two), an options file outside options/ by
    its path, every solve to the tolerance, frame 0 with its peak memory (two processes' on two ranks)."""
    from petsc_htp.bench.studies.scale import run

    mine = tmp_path / "mine.opts"
    mine.write_text(f"-options_file {Path(__file__).resolve().parent.parent / 'options' / 'cg_jacobi.opts'}\n")
    out = tmp_path / "scale"
    assert main(["--quick", "--out", str(out), "--studies", "scale", "--methods", "cg_htp", "cg_gamg", "amgcl",
                 str(mine), "--scale-sides-2d", "48", "64", *env["common"]]) == 0
    rows = rows_of(out, "scale")
    runs = {(r["dim"], r["side"], r["ranks"], r["method"]) for r in rows}
    grids = [(2, 48), (2, 64), (3, 10)]
    assert runs == {(d, s, k, m) for d, s in grids for k in (1, 2) for m in ("cg_htp", "cg_gamg", "amgcl", "mine")
                    if k == 1 or m != "amgcl"}, runs
    for r in rows:
        assert r["ok"] and r["relres"] <= 1e-7 and r["n"] == r["side"] ** r["dim"], r
        assert r["mode"] == ("single" if r["frame"] == 0 else "sequence") and r["frame"] in (0, 1)
        if r["frame"] == 0:
            assert 0 <= r["solve_rss_mb"] < r["peak_rank_mb"] <= r["peak_rss_mb"], r
            assert (r["peak_rss_mb"] > 1.5 * r["peak_rank_mb"]) == (r["ranks"] == 2), r
    assert any(r["iterations"] > 0 for r in rows if r["method"] == "cg_htp")
    report = (out / "report.md").read_text()
    assert "## At scale: the DMDA program on 1 and several ranks" in report and "| N = 2 304 | N = 4 096 |" in report
    assert "| 2-D, 2 ranks | 2 304 |" in report and "not run" in report and (out / "scale.png").stat().st_size
    failed, = run(resolve_method("amgcl"), 2, 48, 2, 0)
    assert not failed["ok"] and "amgcl is a serial solver: run it on one rank" in failed["error"], failed
    bad = tmp_path / "bad.opts"                      # raises on both ranks: one failure row, the cause named
    bad.write_text(f"-options_file {mine}\n-pc_type python\n-pc_python_type petsc_htp.HTPPC\n-htp_direct_max 0\n"
                   "-htp_variant multilevel\n-htp_ml_damping 2.5\n")
    failed, = run(resolve_method(str(bad)), 2, 48, 2, 1)
    assert failed["failure"] == "EXCEPTION" and "htp_ml_damping in (0, 2)" in failed["error"], failed
