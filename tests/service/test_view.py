"""The planner's page (service/view.py): signed links, access, the data routes against the library they
reuse (trace, surface mesh), and the page itself in headless Chromium.

One small job (the 160 test piece, one pose, 1 mm dexels, the robot file's friction) on a real server
serves every job test in this module. The browser tests drive the system's chromium through Playwright;
they skip when either is missing, unless ``GREYBENCH_BROWSER_TESTS=required`` (set by ``.ci/run``), where
they fail instead.
"""
from __future__ import annotations

import json
import struct
import time
from pathlib import Path

import numpy as np
import pytest

import service
from service.view import sign, verify

from .conftest import HEADERS, KEY, ROBOT_FRICTION, Server, server_env, wait_for, watched_page

JOB_ID = "0123456789abcdef0123456789abcdef"


# ---- signed links ---------------------------------------------------------------------------------------
def test_signed_link_accepted_until_expiry_and_only_for_its_job():
    key = b"k" * 32
    tok = sign(key, JOB_ID, 1_000_000)
    assert verify(key, tok, JOB_ID, now=999_999)
    assert not verify(key, tok, JOB_ID, now=1_000_000)            # expired at its expiry second
    assert not verify(key, tok, "f" * 32, now=0)                  # another job
    assert not verify(b"x" * 32, tok, JOB_ID, now=0)              # another secret


def test_forged_links_refused():
    key = b"k" * 32
    job, exp, mac = sign(key, JOB_ID, 2_000_000).split(".")
    later = f"{job}.{int(exp) + 3600}.{mac}"                      # expiry pushed back, MAC kept
    flipped = f"{job}.{exp}.{mac[:-1] + ('A' if mac[-1] != 'A' else 'B')}"
    for tok in (later, flipped, f"{job}.{exp}", "", None, f"{job}.{exp}.{mac}.x", "a" * 300):
        assert not verify(key, tok, JOB_ID, now=0), tok


# ---- access and plain answers (no job needed) ----------------------------------------------------------
def test_page_without_key_is_the_key_form_and_data_refused(client):
    r = client.get(f"/simulations/{JOB_ID}/view")
    assert r.status_code == 401 and r.headers["content-type"].startswith("text/html")
    assert 'id="login-form"' in r.text and JOB_ID not in r.text
    for tail in ("view/data", "view/files/report.json", "view/workpiece/near/mesh",
                 "view/workpiece/near/click?x_mm=0&y_mm=0&z_mm=0"):
        r = client.get(f"/simulations/{JOB_ID}/{tail}")
        assert r.status_code == 401, tail
        r = client.get(f"/simulations/{JOB_ID}/{tail}", params={"token": "forged.1.x"})
        assert r.status_code == 401, tail
    assert client.post(f"/simulations/{JOB_ID}/view-link").status_code == 401


def test_unknown_job_is_a_clear_404_page(client):
    r = client.get(f"/simulations/{JOB_ID}/view", headers=HEADERS)
    assert r.status_code == 404 and "Job not found" in r.text and "Traceback" not in r.text
    assert client.post(f"/simulations/{JOB_ID}/view-link", headers=HEADERS).status_code == 404
    assert client.get(f"/simulations/{JOB_ID}/view/data", headers=HEADERS).status_code == 404


def test_unfinished_job_is_a_clear_409_page(client):
    from service.jobs import JobKind, owner_of

    store = client.app.state.store
    rec = store.create(JobKind.simulation, {"poses": []}, boot="test", owner=owner_of(KEY))  # queued, never started
    r = client.get(f"/simulations/{rec.id}/view", headers=HEADERS)
    assert r.status_code == 409 and "queued" in r.text and "Traceback" not in r.text
    link = client.post(f"/simulations/{rec.id}/view-link", headers=HEADERS).json()
    assert client.get(link["url"]).status_code == 409                   # a valid link, still unfinished
    assert client.get(f"/simulations/{rec.id}/view/data", headers=HEADERS).status_code == 409
    # a compensation job id is not a simulation
    assert client.get(f"/compensations/{rec.id}/view", headers=HEADERS).status_code == 404


#: Table-2 rows of a finished compensation [mm], as simulate.compensation.report's summary gives them.
COMPENSATED_ROWS = [{"name": "circle diameter", "tolerance": 0.02, "before": 0.05, "after": 0.012},
                    {"name": "slope angle", "tolerance": 0.02, "before": -0.004, "after": -0.009}]


#: a gear the corrected program leaves rattling, as simulate.compensation.report's summary gives it
GEARS = [{"section": "square: contour at z = 0 mm", "line": 17, "text": "G1 X-55 Y-60 Z0", "joint": 1,
          "flank_changes_before": 4, "flank_changes_after": 52, "in_play_before": 0.03, "in_play_after": 0.51}]


def _fake_compensation(store, jobs_dir) -> str:
    """A succeeded compensation job with a summary and a deviation plot (the view reads only these)."""
    from PIL import Image

    from service.jobs import JobKind, JobState, folder_digests, owner_of

    rec = store.create(JobKind.compensation, {}, boot="test", owner=owner_of(KEY))
    out = jobs_dir / rec.id / "out"
    out.mkdir(parents=True)
    Image.new("RGB", (60, 40), (200, 30, 30)).save(out / "deviation.png")
    (out / "summary.json").write_text("{}")
    result = {"evaluation": {"rows_mm": COMPENSATED_ROWS, "sum_before_mm": 0.054, "sum_after_mm": 0.021,
                             "ratio": 0.021 / 0.054, "score_before": 2.7, "score_after": 1.05},
              "best_iteration": 2, "max_offset_mm": 0.31, "time_ratio": 1.004, "gears_rattling": GEARS}
    assert store.finish(rec.id, "test", JobState.succeeded, result=result, files=folder_digests(jobs_dir / rec.id))
    return rec.id


def test_compensation_page_shows_before_and_after(client):
    job_id = _fake_compensation(client.app.state.store, client.app.state.manager.jobs_dir)
    assert client.get(f"/compensations/{job_id}/view", headers=HEADERS).status_code == 200
    assert client.get(f"/simulations/{job_id}/view", headers=HEADERS).status_code == 404   # not a simulation
    data = client.get(f"/compensations/{job_id}/view/data", headers=HEADERS).json()
    sections = {s["type"]: s for s in data["sections"]}
    rows = sections["before-after"]["rows"]
    for got, want in zip(rows, COMPENSATED_ROWS, strict=True):
        assert got["name"] == want["name"]
        assert got["before_um"] == pytest.approx(want["before"] * 1e3)
        assert got["after_um"] == pytest.approx(want["after"] * 1e3)
        assert got["tolerance_um"] == pytest.approx(want["tolerance"] * 1e3)
    assert sections["table"]["rows"] == [["square: contour at z = 0 mm", "17: G1 X-55 Y-60 Z0", "A1", 4, 52,
                                          pytest.approx(3.0), pytest.approx(51.0)]]
    image = client.get(sections["image"]["url"], headers=HEADERS)
    assert image.status_code == 200 and image.content[:4] == b"\x89PNG"
    assert {f["name"] for f in sections["files"]["files"]} == {"out/deviation.png", "out/summary.json"}
    # an altered result file is refused (409) and marks the job failed, as the API's downloads do
    (client.app.state.manager.jobs_dir / job_id / "out" / "summary.json").write_text("{1}")
    assert client.get(f"/compensations/{job_id}/view/files/out/summary.json", headers=HEADERS).status_code == 409
    assert client.get(f"/compensations/{job_id}/view", headers=HEADERS).status_code == 409


def test_static_files_ship_with_the_package(client):
    """three.js is served from the package (no CDN), with its licence and version."""
    r = client.get("/view-static/vendor/three/three.module.js", headers={"Accept-Encoding": "gzip"})
    assert r.status_code == 200 and "three.core.js" in r.text
    assert "MIT" in client.get("/view-static/vendor/three/LICENSE").text
    assert "three 0.187.0" in client.get("/view-static/vendor/three/VERSION").text
    static = Path(service.__file__).parent / "static" / "view"
    text = (static / "index.html").read_text()
    assert "http://" not in text and "https://" not in text   # nothing fetched from elsewhere
    js = (static / "view.js").read_text()
    assert "http://" not in js and "https://" not in js


# ---- one finished job -------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def job(tmp_path_factory):
    """(server, job id, job folder) of one finished iso160 job, pose 'near', 1 mm dexels."""
    d = tmp_path_factory.mktemp("view") / "data"
    srv = Server(data_dir=d, env=server_env(d)).start()
    try:
        with srv.client() as c:
            r = c.post("/simulations", json={"program": "iso160", "pose_set": "iso160", "select": ["near"],
                                             "options": {"spacing_mm": 1.0},
                                             "friction": ROBOT_FRICTION})
            assert r.status_code == 202, r.text
            job_id = r.json()["id"]
            st = wait_for(c, job_id, prefix="/simulations", timeout=1800, interval=0.5)
            assert st["state"] == "succeeded", st
        yield srv, job_id, d / "jobs" / job_id
    finally:
        srv.stop()


def _unframe(data: bytes):
    n = struct.unpack("<I", data[:4])[0]
    header = json.loads(data[4:4 + n])
    return header, data[4 + n:]


def _vw(folder):
    from simulate.machining.virtual_workpiece import VirtualWorkpiece
    return VirtualWorkpiece.load(folder / "workpiece" / "near.npz")


def _top_point(vw) -> np.ndarray:
    """A machined, upward-facing dexel end nearest the part's centre (x, y) [m]: a spot seen from above."""
    pts, sign_, attrs = vw.end_attributes(2)
    ok = (attrs["step"] >= 0) & (sign_ > 0)
    p = pts[ok]
    centre = (p.min(axis=0) + p.max(axis=0)) / 2
    return p[np.argmin(np.hypot(p[:, 0] - centre[0], p[:, 1] - centre[1]) + 1e3 * (p[:, 2] < p[:, 2].max() - 0.05))]


def test_view_data_is_the_report(job):
    srv, job_id, folder = job
    with srv.client() as c:
        data = c.get(f"/simulations/{job_id}/view/data").json()
        report = c.get(f"/simulations/{job_id}/report").json()
    sections = {s["type"]: s for s in data["sections"]}
    rows = sections["ranking"]["rows"]
    assert [r["name"] for r in rows] == [f["name"] for f in report["features"]] and len(rows) == 10
    for r, f in zip(rows, report["features"], strict=True):
        assert r["tolerance_mm"] == f["tolerance_mm"] and r["deviation_mm"]["near"] == f["deviation_mm"]["near"]
    wp = sections["workpiece"]
    assert wp["poses"] == ["near"] and {v["name"] for v in wp["variables"]} >= {"deflection", "force", "switch"}
    assert next(v for v in wp["variables"] if v["name"] == "deflection")["unit"] == "µm"
    names = {f["name"] for f in sections["files"]["files"]}
    assert {"report.json", "report.csv", "ranking.json", "program.nc", "workpiece/near.glb",
            "workpiece/near.npz"} <= names


def test_mesh_and_values_match_the_workpiece(job):
    from simulate.machining.surface_mesh import merge_flat_quads, surface_mesh
    from simulate.machining.virtual_workpiece import step_values

    srv, job_id, folder = job
    vw = _vw(folder)
    with srv.client() as c:
        head, body = _unframe(c.get(f"/simulations/{job_id}/view/workpiece/near/mesh").content)
        vhead, vbody = _unframe(c.get(f"/simulations/{job_id}/view/workpiece/near/values",
                                      params={"variable": "force"}).content)
        bad = c.get(f"/simulations/{job_id}/view/workpiece/near/values", params={"variable": "nope"})
    assert bad.status_code == 422 and [d["field"] for d in bad.json()["detail"]] == ["variable"]   # the enum
    n, m = head["vertices"], head["faces"]
    pos = np.frombuffer(body[:12 * n], "<f4").reshape(n, 3)
    idx = np.frombuffer(body[12 * n:12 * n + 12 * m], "<u4").reshape(m, 3)
    assert len(body) == 12 * n + 12 * m and idx.max() < n
    full = surface_mesh(vw.workpiece, stride=max(1, round(head["lattice_mm"] * 1e-3 / vw.workpiece.spacing)))
    sm = merge_flat_quads(full, full.vertex_step.astype(np.int64))
    assert n < len(full.vertices) / 2       # the untouched stock faces merged
    assert len(sm.vertices) == n and np.allclose(pos, sm.vertices * 1e3, atol=1e-3)
    val = np.frombuffer(vbody, "<f4")
    expected = step_values(vw, sm.vertex_step, "force")     # N: display factor 1
    assert val.shape == (n,) and np.array_equal(np.isnan(val), np.isnan(expected))
    assert np.allclose(val[~np.isnan(val)], expected[~np.isnan(expected)], rtol=1e-6)
    assert vhead["unit"] == "N" and vhead["range"][0] == pytest.approx(np.nanmin(expected), rel=1e-6)
    # the tool deviation: |deflection + tracking error| of the creating step, in µm, the deflection the
    # cutter carried there (the loop's row of the step before: the response to that step's force)
    with srv.client() as c:
        thead, tbody = _unframe(c.get(f"/simulations/{job_id}/view/workpiece/near/values",
                                      params={"variable": "tool_deviation"}).content)
    dev = np.frombuffer(tbody, "<f4")
    ok = sm.vertex_step >= 0
    k = sm.vertex_step[ok]
    d = np.where((k > 0)[:, None], vw.steps.deflection[np.maximum(k - 1, 0)], 0.0) + vw.steps.tracking_error[k]
    assert thead["unit"] == "µm" and np.all(np.isnan(dev[~ok]))
    assert np.allclose(dev[ok], np.sqrt(np.sum(d ** 2, axis=1)) * 1e6, rtol=1e-6)


def test_click_is_what_trace_gives(job):
    from simulate.evaluation.trace import trace_point

    srv, job_id, folder = job
    vw = _vw(folder)
    p = _top_point(vw)
    with srv.client() as c:
        r = c.get(f"/simulations/{job_id}/view/workpiece/near/click",
                  params={"x_mm": p[0] * 1e3, "y_mm": p[1] * 1e3, "z_mm": p[2] * 1e3, "radius_mm": 1.5}).json()
    tr = trace_point(vw, p, 1.5e-3, program=str(folder / "program.nc"))
    assert tr.lines, "the chosen point was machined"
    assert ([(ln["line"], ln["text"], ln["n_ends"]) for ln in r["lines"]]
            == [(t.line, t.text, t.n_ends) for t in tr.lines])
    assert r["n_ends"] == tr.n_ends and r["t_first_s"] == pytest.approx(tr.times[0])
    program = (folder / "program.nc").read_text().splitlines()
    for ln in r["lines"]:
        assert ln["text"] == program[ln["line"] - 1].strip()
    # components: mean |deflection| and |tracking error| of the creating steps, independently gathered
    steps = []
    for axis in range(3):
        pts, _, attrs = vw.end_attributes(axis)
        near = (attrs["step"] >= 0) & (np.linalg.norm(pts - p, axis=1) <= 1.5e-3)
        steps.append(attrs["step"][near])
    st = np.concatenate(steps)
    d = np.linalg.norm(vw.steps.deflection[st], axis=1).mean()
    e = np.linalg.norm(vw.steps.tracking_error[st], axis=1).mean()
    comp = r["components"]
    assert comp["deflection_um"] == pytest.approx(d * 1e6, rel=1e-9)
    assert comp["deflection_share"] == pytest.approx(d / (d + e), rel=1e-9)
    assert comp["deflection_share"] + comp["tracking_error_share"] == pytest.approx(1.0)
    bits = int(np.bitwise_or.reduce(vw.steps.switch[st].astype(np.int64)))
    assert r["reversing_axes"] == [i + 1 for i in range(6) if bits >> i & 1]


def test_click_where_an_axis_reverses_names_it(job):
    """A machined end cut by a step with switching bits: the click names those axes (bit i-1: axis i)."""
    srv, job_id, folder = job
    vw = _vw(folder)
    pts, step, _ = vw.workpiece.ends(0)
    hit = np.flatnonzero((step >= 0) & (vw.steps.switch[np.maximum(step, 0)] != 0))
    assert len(hit), "the job has switching points on the machined surface"
    p, bits = pts[hit[0]], int(vw.steps.switch[step[hit[0]]])
    with srv.client() as c:
        r = c.get(f"/simulations/{job_id}/view/workpiece/near/click",
                  params={"x_mm": p[0] * 1e3, "y_mm": p[1] * 1e3, "z_mm": p[2] * 1e3, "radius_mm": 0.01}).json()
    assert r["n_ends"] >= 1
    assert set(i + 1 for i in range(6) if bits >> i & 1) <= set(r["reversing_axes"]) and r["reversing_axes"]


def test_box_gives_the_lines_that_cut_it(job):
    srv, job_id, folder = job
    vw = _vw(folder)
    p = _top_point(vw) * 1e3
    lo, hi = p - [5, 5, 1], p + [5, 5, 1]
    with srv.client() as c:
        r = c.get(f"/simulations/{job_id}/view/workpiece/near/box",
                  params={"min_mm": ",".join(map(str, lo)), "max_mm": ",".join(map(str, hi))}).json()
        bad = c.get(f"/simulations/{job_id}/view/workpiece/near/box", params={"min_mm": "1,2", "max_mm": "1,2,3"})
    assert bad.status_code == 422 and bad.json()["detail"]["field"] == "min_mm"
    lines = set()
    for axis in range(3):
        pts, _, attrs = vw.end_attributes(axis)
        inside = (attrs["step"] >= 0) & np.all((pts * 1e3 >= lo) & (pts * 1e3 <= hi), axis=1)
        lines |= set(attrs["line"][inside].tolist())
    assert lines and sorted(ln["line"] for ln in r["lines"]) == sorted(lines)


def test_links_and_files(job):
    srv, job_id, folder = job
    import httpx

    with srv.client() as c:
        link = c.post(f"/simulations/{job_id}/view-link", json={"expires_s": 60}).json()
        assert c.post(f"/simulations/{job_id}/view-link", json={"expires_s": 1}).status_code == 422
    assert link["url"].startswith(f"/simulations/{job_id}/view?token=")
    page = httpx.get(srv.url + link["url"])
    assert page.status_code == 200 and "<canvas" not in page.text and 'src="/view-static/view/view.js"' in page.text
    tok = link["token"]
    f = httpx.get(f"{srv.url}/simulations/{job_id}/view/files/report.csv", params={"token": tok})
    assert f.status_code == 200 and f.text.startswith("feature,")
    # the token is for this job only and for the view routes only
    assert httpx.get(f"{srv.url}/simulations/{job_id}/report", params={"token": tok}).status_code == 401
    other = "f" * 32
    assert httpx.get(f"{srv.url}/simulations/{other}/view/data", params={"token": tok}).status_code == 401
    # an expired link (signed with the server's own secret) is refused
    secret = bytes.fromhex((srv.data_dir / "view-secret").read_text())
    old = sign(secret, job_id, int(time.time()) - 1)
    assert httpx.get(f"{srv.url}/simulations/{job_id}/view/data", params={"token": old}).status_code == 401
    assert httpx.get(f"{srv.url}/simulations/{job_id}/view", params={"token": old}).status_code == 401
    assert httpx.get(f"{srv.url}/simulations/{job_id}/view/files/..%2Fjobs.sqlite",
                     params={"token": tok}).status_code in (404, 422)


# ---- the page in a browser (the browser fixture: conftest) ----------------------------------------------
def test_browser_tests_skip_with_a_reason_or_fail_when_required(monkeypatch):
    from . import conftest

    monkeypatch.setattr(conftest, "CHROMIUM", "/nonexistent/chromium")
    monkeypatch.delenv("GREYBENCH_BROWSER_TESTS", raising=False)
    with pytest.raises(pytest.skip.Exception, match="chromium"):
        conftest.require_browser()
    monkeypatch.setenv("GREYBENCH_BROWSER_TESTS", "required")
    with pytest.raises(pytest.fail.Exception, match="chromium"):
        conftest.require_browser()


# Predicates are functions ("() => ..."): playwright evaluates a function once, a bare expression on every
# poll, which the page's CSP (no 'unsafe-eval') refuses.
def _open(browser, url):
    page, problems = watched_page(browser)
    page.goto(url)
    page.wait_for_function("() => window.greybenchView && window.greybenchView.ready", timeout=60_000)
    return page, problems


def test_page_in_chromium(job, browser, tmp_path):
    from PIL import Image

    from simulate.evaluation.trace import trace_point

    srv, job_id, folder = job
    with srv.client() as c:
        link = c.post(f"/simulations/{job_id}/view-link").json()
        report = c.get(f"/simulations/{job_id}/report").json()
    page, problems = _open(browser, srv.url + link["url"])
    # the ranking: ten rows, the job's deviations, in-tolerance cells marked
    table = page.locator("table.table2")
    assert table.locator("tbody tr").count() == 10
    assert table.locator("thead th[data-pose='near']").count() == 1
    cells = table.locator("tbody tr td:nth-child(4)").all_inner_texts()
    for text, f in zip(cells, report["features"], strict=True):
        dev = f["deviation_mm"]["near"]
        assert float(text) == pytest.approx(dev, abs=6e-5)
    marked = table.locator("td.in-tol").count()
    assert marked == sum(abs(f["deviation_mm"]["near"]) <= f["tolerance_mm"] for f in report["features"])
    # the part is drawn: the canvas is not one flat colour and shows the colour map, not just background
    canvas = page.locator(".wp-canvas canvas")
    png = tmp_path / "canvas.png"
    canvas.screenshot(path=str(png))
    img = np.asarray(Image.open(png).convert("RGB")).astype(int)
    background = np.array([0xf4, 0xf4, 0xf4])
    part = np.any(np.abs(img - background) > 12, axis=2)
    assert part.mean() > 0.05, f"only {part.mean():.1%} of the canvas differs from the background"
    assert len(np.unique(img[part].reshape(-1, 3) // 16, axis=0)) > 10, "no colour scale on the part"
    # a click on a known machined point: the page shows the program lines trace gives there
    vw = _vw(folder)
    p = _top_point(vw) * 1e3
    page.evaluate(f"window.greybenchView.workpiece.lookAt({p.tolist()}, [0, -0.2, 1], 160)")
    xy = page.evaluate(f"window.greybenchView.workpiece.project({p[0]}, {p[1]}, {p[2]})")
    page.mouse.click(xy["x"], xy["y"])
    page.wait_for_selector("table.trace-lines", timeout=30_000)
    shown = [int(v) for v in page.locator("table.trace-lines tr[data-line]").evaluate_all(
        "rows => rows.map(r => r.dataset.line)")]
    clicked = np.array([float(v) for v in page.locator(".trace-summary").get_attribute("data-point").split(",")])
    assert np.linalg.norm(clicked - p) < 2.0, f"clicked {clicked} mm, aimed at {p} mm"
    expected = trace_point(vw, clicked * 1e-3, 1.5e-3, program=str(folder / "program.nc"))
    assert shown == [ln.line for ln in expected.lines] and shown
    program = (folder / "program.nc").read_text().splitlines()
    texts = page.locator("table.trace-lines code.line").all_inner_texts()
    assert texts == [program[n - 1].strip() for n in shown]
    # shift + drag: a box around the point lists the lines that cut the machined ends inside it
    page.keyboard.down("Shift")
    page.mouse.move(xy["x"] - 25, xy["y"] - 25)
    page.mouse.down()
    page.mouse.move(xy["x"] + 25, xy["y"] + 25, steps=4)
    page.mouse.up()
    page.keyboard.up("Shift")
    page.wait_for_selector("table.box-lines", timeout=30_000)
    box = page.evaluate("window.greybenchView.lastBox")
    lo, hi = np.array(box["min_mm"]), np.array(box["max_mm"])
    assert np.all(lo <= p + 1e-6) and np.all(p <= hi + 1e-6) and np.all(hi - lo < 60)
    lines = set()
    for axis in range(3):
        pts, _, attrs = vw.end_attributes(axis)
        inside = (attrs["step"] >= 0) & np.all((pts * 1e3 >= lo) & (pts * 1e3 <= hi), axis=1)
        lines |= set(attrs["line"][inside].tolist())
    boxed = page.locator("table.box-lines tr[data-line]").evaluate_all("rows => rows.map(r => +r.dataset.line)")
    assert boxed and sorted(boxed) == sorted(lines)
    # the colour says in or out of tolerance (green, hue 120), then how far out: orange (hue 40) just over
    # the tolerance to red (hue 0) at 10x and beyond; the rank among the poses does not colour the cell
    hues = page.evaluate("[{in_tolerance: true, factor: 0.5, rank: 2}, {in_tolerance: false, factor: 1, rank: 1},"
                         " {in_tolerance: false, factor: 10 ** 0.5, rank: 1}, {in_tolerance: false, factor: 20,"
                         " rank: 1}].map(c => window.greybenchView.cellStyle(c).hue)")
    assert hues == [120, 40, 20, 0]
    # another variable recolours the part; the legend names its unit
    page.select_option(".wp-variable", "force")
    page.wait_for_function("() => window.greybenchView.ready")
    assert page.locator(".wp-unit").inner_text() == "N"
    assert not problems, problems
    page.close()


def test_compensation_page_in_chromium(job, browser):
    from service.jobs import JobStore

    srv, _, _ = job
    job_id = _fake_compensation(JobStore(srv.data_dir / "jobs.sqlite"), srv.data_dir / "jobs")
    with srv.client() as c:
        link = c.post(f"/compensations/{job_id}/view-link").json()
    page, problems = _open(browser, srv.url + link["url"])
    rows = page.locator("section.before-after table tr").all_inner_texts()
    assert len(rows) == 1 + len(COMPENSATED_ROWS)
    assert rows[1].split("\t")[:4] == ["circle diameter", "20", "50.0", "12.0"]
    assert page.locator("section.before-after td.in-tol").count() == 3     # 12 µm; -4 and -9 µm of 20
    gears = page.locator("table[data-id='gears'] tbody tr").all_inner_texts()
    assert [r.split("\t") for r in gears] == [["square: contour at z = 0 mm", "17: G1 X-55 Y-60 Z0", "A1", "4", "52",
                                               "3", "51"]]
    page.wait_for_function("() => document.querySelector('section.image img').naturalWidth === 60")
    assert not problems, problems
    page.close()


def test_key_entered_once_opens_the_page(job, browser):
    srv, job_id, _ = job
    page = browser.new_page()
    page.goto(f"{srv.url}/simulations/{job_id}/view")
    page.wait_for_selector("#login:not([hidden])")
    assert page.locator("table.table2").count() == 0           # no data before a key
    page.fill("#login-key", "not-the-key-0000")
    page.click("#login-form button")
    page.wait_for_function("() => document.querySelector('#login-error').textContent.includes('refused')")
    assert "token=" not in page.url
    page.fill("#login-key", KEY)
    page.click("#login-form button")
    page.wait_for_function("() => window.greybenchView && window.greybenchView.ready", timeout=60_000)
    assert "token=" in page.url and page.locator("table.table2 tbody tr").count() == 10
    # the key stays for the tab's session: the bare page opens again without asking
    page.goto(f"{srv.url}/simulations/{job_id}/view")
    page.wait_for_function("() => window.greybenchView && window.greybenchView.ready", timeout=60_000)
    assert "token=" in page.url
    page.close()
