"""The planner's page tells "is it good" at a glance (service/view.py, static/view): Table-2 cells coloured by
in / out of tolerance with the factor over it before the rank among poses, one colour scale for every pose of
the job (toggle to per-pose), categorical colours for program lines, the job's header, the part in the robot
base frame with its triads, and the printable report.

One job of two poses (the 160 piece's short program: a real cut, seconds per pose) on a real server serves
the module. The expected values come from the job's own files (report.json, the workpiece npz files), read
here independently of the view's code.
"""
from __future__ import annotations

import json
import time

import numpy as np
import pytest

from .conftest import ROBOT_FRICTION, Server, server_env, short_program, wait_for, watched_page

POSES = ("near", "far_rotated")


@pytest.fixture(scope="module")
def job(tmp_path_factory):
    """(server, job id, job folder) of one finished two-pose job on the short iso160 program, 1 mm dexels."""
    d = tmp_path_factory.mktemp("view-colours") / "data"
    srv = Server(data_dir=d, env=server_env(d)).start()
    try:
        with srv.client() as c:
            r = c.post("/simulations", json={"gcode": short_program(), "stock": "iso160", "pose_set": "iso160",
                                             "options": {"spacing_mm": 1.0}, "friction": ROBOT_FRICTION})
            assert r.status_code == 202, r.text
            job_id = r.json()["id"]
            st = wait_for(c, job_id, prefix="/simulations", timeout=1800, interval=0.5)
            assert st["state"] == "succeeded", st
        yield srv, job_id, d / "jobs" / job_id
    finally:
        srv.stop()


def _sections(srv, job_id) -> dict:
    with srv.client() as c:
        data = c.get(f"/simulations/{job_id}/view/data").json()
    return {s["type"]: s for s in data["sections"]}


def _report(folder) -> dict:
    return json.loads((folder / "report.json").read_text())


def _end_values(folder, pose: str, variable: str, factor: float) -> np.ndarray:
    """The variable at every machined dexel end of a pose's workpiece, in display units (from the npz)."""
    from simulate.machining.virtual_workpiece import VirtualWorkpiece, step_values

    vw = VirtualWorkpiece.load(folder / "workpiece" / f"{pose}.npz")
    steps = np.concatenate([a["step"][a["step"] >= 0] for a in (vw.end_attributes(k)[2] for k in range(3))])
    return step_values(vw, steps, variable) * factor


# ---- the data the page gets --------------------------------------------------------------------------------
def test_cells_say_in_tolerance_factor_and_rank(job):
    srv, job_id, folder = job
    rows = _sections(srv, job_id)["ranking"]["rows"]
    report = _report(folder)
    assert len(rows) == len(report["features"]) == 10
    for r, f in zip(rows, report["features"], strict=True):
        mags = {p: abs(f["deviation_mm"][p]) for p in POSES}
        for p in POSES:
            c = r["cells"][p]
            assert c["in_tolerance"] == (mags[p] <= f["tolerance_mm"])
            assert c["factor"] == pytest.approx(mags[p] / f["tolerance_mm"], rel=1e-9)
            assert c["rank"] == 1 + sum(m < mags[p] for m in mags.values())
    # the job has what the colour rule is about: a row whose best pose is out of tolerance
    assert any(min(r["cells"].values(), key=lambda c: c["rank"])["in_tolerance"] is False for r in rows)


def test_job_scale_spans_every_pose(job):
    """The shared scale of a variable is the smallest and largest value at the machined ends of all poses."""
    srv, job_id, folder = job
    wp = _sections(srv, job_id)["workpiece"]
    factors = {v["name"]: v["factor"] for v in wp["variables"]}
    for variable in ("deflection", "force", "time"):
        vals = np.concatenate([_end_values(folder, p, variable, factors[variable]) for p in POSES])
        assert wp["scales"][variable] == pytest.approx([np.nanmin(vals), np.nanmax(vals)], rel=1e-6)
        own = [_end_values(folder, p, variable, factors[variable]) for p in POSES]
        assert [np.nanmax(v) for v in own] != pytest.approx([np.nanmax(vals)] * 2)   # the poses differ
    # each pose's own range (the values route) lies inside the job's
    with srv.client() as c:
        for p in POSES:
            data = c.get(f"/simulations/{job_id}/view/workpiece/{p}/values", params={"variable": "deflection"}).content
            n = int.from_bytes(data[:4], "little")
            lo, hi = json.loads(data[4:4 + n])["range"]
            assert wp["scales"]["deflection"][0] <= lo + 1e-9 and hi <= wp["scales"]["deflection"][1] + 1e-9
    assert {v["name"] for v in wp["variables"] if v["categorical"]} == {"line", "switch"}
    assert len(wp["categorical"]) == 20 and len({tuple(c) for c in wp["categorical"]}) == 20


def test_header_names_the_inputs(job):
    srv, job_id, folder = job
    head = _sections(srv, job_id)["header"]
    items = {k: v for k, v, *_ in head["items"]}
    assert items["program"] == "gcode" and items["robot"] == "max100" and items["pose file"] == "iso160.json"
    assert items["dexel spacing [mm]"] == 1.0 and items["poses"] == "near, far_rotated"
    assert items["ran (UTC)"].startswith("20") and items["ran (UTC)"].count("Z") == 2
    kinds = {f"A{f['joint']}": f["kind"] for f in _report(folder)["poses"][0]["friction"]}
    assert [a for a, _ in head["friction"]] == [f"A{j}" for j in range(1, 7)]
    for axis, text in head["friction"]:
        assert text.startswith(kinds[axis]) and "robot-file" in text


def test_frames_are_the_pose_file_placements(job):
    from simulate.toolpath.placement import parse_poses

    srv, job_id, _ = job
    frames = _sections(srv, job_id)["workpiece"]["frames"]
    from tests.service.conftest import DATA

    placements = {p.name: p for p in parse_poses(json.loads((DATA / "poses" / "iso160.json").read_text()))}
    for p in POSES:
        T = np.array(frames[p]).reshape(4, 4)
        assert np.allclose(T[:3, :3], placements[p].T[:3, :3]) and np.allclose(T[:3, 3], placements[p].xyz * 1e3)


# ---- the page in Chromium -------------------------------------------------------------------------------------
def _open(browser, srv, job_id):
    with srv.client() as c:
        link = c.post(f"/simulations/{job_id}/view-link").json()
    page, problems = watched_page(browser)
    t0 = time.perf_counter()
    page.goto(srv.url + link["url"])
    page.wait_for_function("() => window.greybenchView && window.greybenchView.ready", timeout=60_000)
    return page, problems, time.perf_counter() - t0


def _rgb(css: str) -> tuple[int, ...]:
    return tuple(int(v) for v in css[css.index("(") + 1:css.index(")")].split(",")[:3])


def test_out_of_tolerance_best_cell_is_not_shown_good(job, browser):
    srv, job_id, folder = job
    report = _report(folder)
    page, problems, _ = _open(browser, srv, job_id)
    checked = 0
    for i, f in enumerate(report["features"]):
        for p in POSES:
            cell = page.locator(f"table.table2 tbody tr:nth-child({i + 1}) td[data-pose='{p}']")
            r, g, b = _rgb(cell.evaluate("e => getComputedStyle(e).backgroundColor"))
            ok = abs(f["deviation_mm"][p]) <= f["tolerance_mm"]
            assert ("in-tol" in cell.get_attribute("class")) == ok
            if ok:
                assert g > r + 20, (f["name"], p, (r, g, b))            # green
            else:
                assert r > g + 20, (f["name"], p, (r, g, b))            # orange to red, also for the best pose
                # the factor over tolerance is shown beside the value (the style sheet draws data-times)
                factor = abs(f["deviation_mm"][p]) / f["tolerance_mm"]
                text = f"{factor:.0f}" if factor >= 10 else f"{factor:.1f}"
                assert cell.evaluate("e => getComputedStyle(e, '::after').content") == f'" {text}×"'
            best = abs(f["deviation_mm"][p]) <= min(abs(f["deviation_mm"][q]) for q in POSES)
            assert ("best" in cell.get_attribute("class")) == best
            checked += not ok and best
    assert checked, "no out-of-tolerance best cell to check"
    assert page.locator("table.table2 + p.key").inner_text().count("in tolerance") >= 1
    assert not problems, problems
    page.close()


def test_one_scale_for_all_poses_and_per_pose_on_request(job, browser):
    srv, job_id, _ = job
    wp = _sections(srv, job_id)["workpiece"]
    page, problems, _ = _open(browser, srv, job_id)
    view = "window.greybenchView"
    page.select_option(".wp-variable", "deflection")
    page.wait_for_function(f"() => {view}.ready")
    shown = {}
    for p in POSES:
        page.select_option(".wp-pose", p)
        page.wait_for_function(f"() => {view}.ready && {view}.workpiece.pose === '{p}'")
        s = page.evaluate(f"{view}.scale")
        shown[p] = (s["lo"], s["hi"])
        assert s["shared"] and (s["lo"], s["hi"]) == pytest.approx(tuple(wp["scales"]["deflection"]), rel=1e-6)
    # per pose: the pose's own range (the values route's), which differs between the poses
    page.uncheck(".wp-shared")
    page.wait_for_function(f"() => {view}.ready && !{view}.scale.shared")
    own = page.evaluate(f"{view}.scale")
    with srv.client() as c:
        data = c.get(f"/simulations/{job_id}/view/workpiece/{POSES[-1]}/values",
                     params={"variable": "deflection"}).content
    n = int.from_bytes(data[:4], "little")
    assert (own["lo"], own["hi"]) == pytest.approx(tuple(json.loads(data[4:4 + n])["range"]), rel=1e-5)
    assert "this pose only" in page.locator(".wp-scale-note").inner_text()
    # program lines: categories, each line its colour of 20 (neighbours differ), listed in the key or counted
    page.select_option(".wp-variable", "line")
    page.wait_for_function(f"() => {view}.ready && {view}.scale.categorical")
    cats = page.evaluate(f"{view}.scale.categories")
    program = short_program().splitlines()
    assert cats and all(1 <= k <= len(program) for k in cats)
    cols = page.evaluate(f"{view}.workpiece.section.categorical")
    assert all(cols[k % 20] != cols[(k + 1) % 20] for k in cats)
    assert page.locator(".wp-scale").is_hidden() and page.locator(".wp-cats").inner_text()
    assert not problems, problems
    page.close()


def test_triads_base_and_page_width(job, browser, tmp_path):
    from PIL import Image

    srv, job_id, _ = job
    page, problems, _ = _open(browser, srv, job_id)
    names = page.evaluate("""() => { const s = window.greybenchView.workpiece.scene, out = [];
        s.traverse(o => { if (o.name) out.push(o.name); }); return out; }""")
    assert {"workpiece frame", "base frame", "robot base"} <= set(names)
    assert {f"base frame-{a}" for a in "xyz"} <= set(names) and {f"workpiece-{a}" for a in "xyz"} <= set(names)
    # the workpiece triad stands at the pose's origin in the base frame [mm]
    origin = page.evaluate("""() => { const v = window.greybenchView.workpiece.toWorld(0, 0, 0);
        return [v.x, v.y, v.z]; }""")
    assert origin == pytest.approx([1500.0, 0.0, -100.0], abs=1e-3)     # iso160.json, pose near
    # the canvas uses the page's width
    width = page.evaluate("() => [document.querySelector('.wp-canvas canvas').clientWidth, "
                          "document.querySelector('main').clientWidth]")
    assert width[0] > 0.9 * width[1] - 60
    # the triad is drawn: its red x arrow shows on the canvas
    shot = tmp_path / "triad.png"
    page.locator(".wp-canvas canvas").screenshot(path=str(shot))
    img = np.asarray(Image.open(shot).convert("RGB")).astype(int)
    red = (img[..., 0] > 180) & (img[..., 1] < 80) & (img[..., 2] < 80)
    assert red.sum() > 50, red.sum()
    assert not problems, problems
    page.close()


def test_page_opens_fast_after_the_first_open(job, browser):
    """A planner's browser opening the page again (its HTTP cache, the server's mesh cache warm): under 2 s."""
    srv, job_id, _ = job
    with srv.client() as c:
        link = c.post(f"/simulations/{job_id}/view-link").json()
    context = browser.new_context(viewport={"width": 1280, "height": 1000})
    problems: list[str] = []
    times = []
    for _ in range(2):
        page = context.new_page()
        page.on("console", lambda m: problems.append(m.text) if m.type == "error" else None)
        page.on("pageerror", lambda e: problems.append(str(e)))
        t0 = time.perf_counter()
        page.goto(srv.url + link["url"])
        page.wait_for_function("() => window.greybenchView && window.greybenchView.ready", timeout=60_000)
        times.append(time.perf_counter() - t0)
        page.close()
    context.close()
    assert times[1] < 2.0, f"{times[1]:.2f} s (first open {times[0]:.2f} s)"
    assert not problems, problems


def pdf_pages(pdf: bytes, tmp_path) -> tuple[list, str]:
    """Every page of a PDF rendered by poppler's pdftoppm (arrays), and its text (pdftotext)."""
    import shutil
    import subprocess

    from PIL import Image

    if not shutil.which("pdftoppm"):
        pytest.skip("no pdftoppm (apt-get install poppler-utils)")
    path = tmp_path / "report.pdf"
    path.write_bytes(pdf)
    subprocess.run(["pdftoppm", "-r", "40", "-png", str(path), str(tmp_path / "page")], check=True)
    pages = [np.asarray(Image.open(p).convert("L")) for p in sorted(tmp_path.glob("page-*.png"))]
    text = subprocess.run(["pdftotext", "-layout", str(path), "-"], check=True, capture_output=True, text=True).stdout
    return pages, text


def test_printable_report_from_the_page(job, browser, tmp_path):
    import httpx

    srv, job_id, folder = job
    page, problems, _ = _open(browser, srv, job_id)
    href = page.locator("section.header a.pdf-link").get_attribute("href")
    assert href.startswith(f"/simulations/{job_id}/view/report.pdf?token=")
    assert not problems, problems
    page.close()
    r = httpx.get(srv.url + href, timeout=600)
    assert r.status_code == 200 and r.headers["content-type"] == "application/pdf" and r.content[:5] == b"%PDF-"
    pages, text = pdf_pages(r.content, tmp_path)
    assert len(pages) >= 2 and all(p.std() > 1 for p in pages), "a blank page"     # every page renders
    # the listed parts: the inputs and models, Table 2 with the job's numbers, a part per pose, the files
    for words in ("Job", "max100", "iso160.json", "friction model", "Table 2", "Virtual workpiece", "Result files",
                  "pose near", "pose far_rotated", "report.json"):
        assert words in text, words
    report = _report(folder)
    for f in report["features"]:
        assert f"{f['deviation_mm']['near']:+.4f}" in text, f["name"]
    # the parts are pictures: a page holds a large coloured (non-grey) area
    from PIL import Image

    colour = [np.asarray(Image.open(p).convert("RGB")).astype(int) for p in sorted(tmp_path.glob("page-*.png"))]
    # (Table 2's coloured cells make one such page; the short test program's part is mostly grey stock)
    shares = sorted(float((np.ptp(c, axis=2) > 60).mean()) for c in colour)
    assert len(shares) >= 2 and shares[-2] > 0.01, f"coloured share per page: {shares}"
    # without a key or a link: refused
    assert httpx.get(f"{srv.url}/simulations/{job_id}/view/report.pdf").status_code == 401
