"""The planner's page of circle and placement-search jobs (service/view.py): the sections against the files a
finished job wrote, the access rules, and the page in headless Chromium.

The jobs are written into the store directly (no simulation): a circle job's files come from
:func:`simulate.evaluation.circle.write_outputs` on a synthetic trace with known numbers, a placement search's
files are written in the format of :mod:`simulate.placement.report`.
"""
from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest

from .conftest import HEADERS, KEY, ROBOT_FRICTION, Server, server_env, watched_page

#: The synthetic circle: 1 µm-per-degree free of spikes, two reversals with known heights.
ROUNDNESS_UM, RADIUS_ERROR_UM = 12.5, -3.25
SPIKES = [(90.0, 1, 7.5), (90.0, 6, 7.5), (270.0, 2, -4.0)]
#: per reversal of SPIKES: (spike, lost motion) [µm]; joints reversing at the same sample share one split, as
#: simulate.evaluation.circle evaluates them
SPLITS = [(1.5, 6.0), (1.5, 6.0), (-3.0, -1.0)]
#: the spike table: one row per reversal, naming every joint that reverses there
REVERSAL_ROWS = [[90.0, "A1, A6", 1.5, 6.0, 7.5], [270.0, "A2", -3.0, -1.0, -4.0]]

#: The synthetic placement search: best found placement against two given poses.
GIVEN = [{"name": "near", "xyz": [1.5, 0.0, -0.1], "rpy": [0.0, 0.0, 0.0]},
         {"name": "far_rotated", "xyz": [1.9, 0.3, -0.1], "rpy": [0.0, 0.0, 0.5235987755982988]}]
SCORES = {"near": 4.0, "far_rotated": 5.0}
BEST = {"name": "optimised", "candidate": "c7", "origin": "sampled", "xyz_m": [1.62, -0.08, -0.05],
        "rpy_rad": [0.0, 0.0, 0.25], "score": 3.0, "in_tolerance": 7}


def _circle_job(store, jobs_dir, *, legacy: bool = False) -> str:
    """A succeeded circle job whose files :func:`write_outputs` wrote from a synthetic result; ``legacy``:
    its summary.json without ``largest_excursion_um`` (a job stored before that name, with only the
    deprecated ``largest_spike_um``)."""
    from service.jobs import JobKind, JobState, folder_digests, owner_of
    from simulate.evaluation.circle import CircleResult, ReversalSpike, write_outputs

    rec = store.create(JobKind.circle, {}, boot="test", owner=owner_of(KEY))
    ang = np.linspace(0.0, 360.0, 3601)[:-1]
    dev = ROUNDNESS_UM / 2 * np.cos(np.radians(2 * ang))        # an oval: peak-to-valley = roundness
    spikes = tuple(ReversalSpike(angle_deg=a, joint=j, height_um=h, peak_angle_deg=a + 1, spike_um=sp,
                                 lost_motion_um=lm) for (a, j, h), (sp, lm) in zip(SPIKES, SPLITS, strict=True))
    res = CircleResult(angle_deg=ang, deviation_um=dev, q=np.zeros((len(ang), 6)), roundness_um=ROUNDNESS_UM,
                       radius_error_um=RADIUS_ERROR_UM, center_offset_um=np.array([0.5, -0.25]), spikes=spikes,
                       radius_m=0.05, feed_m_s=2000 / 6e4, plane="xy")
    options = {"radius_mm": 50.0, "feed_mm_min": 2000.0, "plane": "xy", "center_mm": [0, 0, 0], "cw": False,
               "friction": True, "backlash": True, "friction_scale": 1.0, "ff_friction": False}
    info = write_outputs(res, jobs_dir / rec.id / "out", title="test",
                         info={"robot": "max100", "pose": "near", **options, "friction_models": {}})
    if legacy:
        del info["largest_excursion_um"]
        (jobs_dir / rec.id / "out" / "summary.json").write_text(json.dumps(info, indent=1), encoding="utf-8")
    assert store.finish(rec.id, "test", JobState.succeeded, result=info, files=folder_digests(jobs_dir / rec.id))
    return rec.id


def _placement_job(store, jobs_dir, *, history: int = 6) -> str:
    """A succeeded placement search: summary.json, best.json, history.csv, heatmap.png, report.md."""
    import pandas as pd
    from PIL import Image

    from identify.records import write_table
    from service.jobs import JobKind, JobState, folder_digests, owner_of

    rec = store.create(JobKind.placement_search, {}, boot="test", owner=owner_of(KEY))
    out = jobs_dir / rec.id / "out"
    out.mkdir(parents=True)
    given = [{"name": g["name"], "score": SCORES[g["name"]], "in_tolerance": 5} for g in GIVEN]
    summary = {"best": BEST, "given": given, "best_given": "near", "improvement": 0.25, "score_reduction": 1.0,
               "candidates": {"simulated": history, "skipped": 1, "unreachable": 0}, "wall_time_s": 55.0,
               "budget_s": 60.0, "stop_reason": "budget", "backend": "processes", "seed": 3,
               "heatmap": "compliance proxy (fewer than four simulations to fit a score prediction)"}
    (out / "summary.json").write_text(json.dumps(summary))
    (out / "best.json").write_text(json.dumps({"poses": GIVEN + [{"name": "optimised", "xyz": BEST["xyz_m"],
                                                                  "rpy": BEST["rpy_rad"]}]}))
    rows = []
    scores = [SCORES["near"], SCORES["far_rotated"], 4.5, 3.5, 3.8, BEST["score"]][:history]
    for i, s in enumerate(scores):
        rows.append({"index": i, "name": GIVEN[i]["name"] if i < 2 else f"c{i}", "origin": "given" if i < 2 else
                     "sampled", "status": "simulated", "x_mm": 1500.0 + i, "y_mm": 0.0, "z_mm": -100.0,
                     "yaw_deg": 0.0, "score": s, "in_tolerance": 5, "switching_points": 4,
                     "compliance_um_per_n": 1.5, "message": ""})
    rows.append({**rows[-1], "index": history, "name": "c_skip", "origin": "sampled", "status": "skipped",
                 "score": float("nan")})
    write_table(pd.DataFrame(rows), out / "history.csv")
    Image.new("RGB", (80, 60), (30, 90, 200)).save(out / "heatmap.png")
    (out / "report.md").write_text("# Placement search\n")
    assert store.finish(rec.id, "test", JobState.succeeded, result=summary, files=folder_digests(jobs_dir / rec.id))
    return rec.id


def _sections(client, prefix, job_id):
    r = client.get(f"{prefix}/{job_id}/view/data", headers=HEADERS)
    assert r.status_code == 200, r.text
    return r.json()["sections"]


# ---- API ---------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("legacy", [False, True])
def test_circle_page_shows_the_circle_numbers(client, legacy):
    job_id = _circle_job(client.app.state.store, client.app.state.manager.jobs_dir, legacy=legacy)
    assert client.get(f"/circles/{job_id}/view", headers=HEADERS).status_code == 200
    secs = _sections(client, "/circles", job_id)
    by_type = {s["type"]: s for s in secs}
    items = {k: v for k, v, *_ in by_type["summary"]["items"]}
    # every number row names its decimals (one format per row, whole values too)
    assert all(len(it) == 3 for it in by_type["summary"]["items"] if isinstance(it[1], float))
    assert items["roundness (circular deviation G, ISO 230-4) [µm]"] == pytest.approx(ROUNDNESS_UM)
    assert items["radius error (least-squares radius - nominal) [µm]"] == pytest.approx(RADIUS_ERROR_UM)
    assert items["largest excursion after a reversal (lost motion and spike) [µm]"] == pytest.approx(7.5)
    assert items["largest reversal spike, beyond the settled trace [µm]"] == pytest.approx(3.0)
    assert items["largest lost motion, step of the settled trace [µm]"] == pytest.approx(6.0)
    assert by_type["table"]["columns"] == ["angle [deg]", "joints reversing", "spike [µm]", "lost motion [µm]",
                                           "excursion [µm]"]
    assert by_type["table"]["rows"] == REVERSAL_ROWS
    # the polar trace is the CSV's, thinned to at most POLAR_MAX_POINTS samples; the oval's extremes survive
    from service.view import POLAR_MAX_POINTS

    s = by_type["polar"]["series"][0]
    assert 1000 < len(s["angle_deg"]) <= POLAR_MAX_POINTS
    assert max(s["deviation_um"]) - min(s["deviation_um"]) == pytest.approx(ROUNDNESS_UM, rel=1e-3)
    i = s["angle_deg"].index(45.0)
    assert s["deviation_um"][i] == pytest.approx(0.0, abs=1e-3)       # cos(90 deg)
    # joints reversing together share one mark
    # joints reversing together share one mark, labelled with the spike and the lost motion as the CLI's table
    assert by_type["polar"]["marks"] == [{"angle_deg": 90.0, "label": "A1+A6 spike +1.5 µm, lost motion +6.0 µm"},
                                         {"angle_deg": 270.0, "label": "A2 spike -3.0 µm, lost motion -1.0 µm"}]
    # the polar plot once (drawn by the page); the job's PNG of it is a download
    assert "image" not in by_type
    png = client.get(next(f["url"] for f in by_type["files"]["files"] if f["name"] == "out/circle.png"),
                     headers=HEADERS)
    assert png.status_code == 200 and png.content[:4] == b"\x89PNG"
    assert {f["name"] for f in by_type["files"]["files"]} == {"out/circle.csv", "out/circle.png", "out/summary.json"}
    csv = client.get(next(f["url"] for f in by_type["files"]["files"] if f["name"] == "out/circle.csv"),
                     headers=HEADERS)
    assert csv.status_code == 200 and csv.text.startswith("angle_deg,radial_deviation_um")


def test_circle_without_reversals_says_so(client, tmp_path):
    from service.jobs import JobKind, owner_of

    store, jobs = client.app.state.store, client.app.state.manager.jobs_dir
    job_id = _circle_job(store, jobs)
    # rewrite the job as one without spikes (a new job: the recorded digests must match)
    summary = json.loads((jobs / job_id / "out" / "summary.json").read_text())
    rec = store.create(JobKind.circle, {}, boot="test", owner=owner_of(KEY))
    (jobs / rec.id / "out").mkdir(parents=True)
    (jobs / rec.id / "out" / "summary.json").write_text(json.dumps({**summary, "reversal_spikes": []}))
    from service.jobs import JobState, folder_digests

    assert store.finish(rec.id, "test", JobState.succeeded, result={}, files=folder_digests(jobs / rec.id))
    table = next(s for s in _sections(client, "/circles", rec.id) if s["type"] == "table")
    assert table["rows"] == [] and "no joint reverses" in table["empty"]


def test_joints_with_different_numbers_at_one_angle_keep_their_rows():
    from service.view import reversal_groups

    same = {"angle_deg": 92.2, "spike_um": 4.0, "lost_motion_um": 1.0, "height_um": 5.0}
    spikes = [{**same, "joint": "A1"}, {**same, "joint": "A6"}, {**same, "joint": "A3", "spike_um": 2.0}]
    assert [[r["joint"] for r in g] for g in reversal_groups(spikes)] == [["A1", "A6"], ["A3"]]


def test_circle_and_search_pdfs(client, tmp_path):
    """Every kind's page prints: the PDF renders page by page and holds the page's numbers."""
    from .test_view_colours import pdf_pages

    store, jobs = client.app.state.store, client.app.state.manager.jobs_dir
    for prefix, job_id, words in (("/circles", _circle_job(store, jobs), ["Circle test", "Reversal spikes",
                                                                          "A1, A6", f"{ROUNDNESS_UM:.1f}"]),
                                  ("/placement-searches", _placement_job(store, jobs), ["Placement search",
                                                                                        "optimised", "3.0000"])):
        data = client.get(f"{prefix}/{job_id}/view/data", headers=HEADERS).json()
        assert data["pdf"].startswith(f"{prefix}/{job_id}/view/report.pdf")
        r = client.get(data["pdf"], headers=HEADERS)
        assert r.status_code == 200 and r.content[:5] == b"%PDF-"
        (tmp_path / prefix.strip("/")).mkdir()
        pages, text = pdf_pages(r.content, tmp_path / prefix.strip("/"))
        assert pages and all(p.std() > 1 for p in pages)
        for w in words:
            assert w in text, (prefix, w)


def test_placement_page_best_against_given(client):
    job_id = _placement_job(client.app.state.store, client.app.state.manager.jobs_dir)
    assert client.get(f"/placement-searches/{job_id}/view", headers=HEADERS).status_code == 200
    secs = _sections(client, "/placement-searches", job_id)
    poses = next(s for s in secs if s.get("id") == "poses")
    rows = {r[0]: dict(zip(poses["columns"], r, strict=True)) for r in poses["rows"]}
    assert list(rows) == ["optimised", "near", "far_rotated"] and poses["highlight"] == [0]
    best = rows["optimised"]
    assert [best["x [mm]"], best["y [mm]"], best["z [mm]"]] == pytest.approx([1620.0, -80.0, -50.0])
    assert best["yaw [deg]"] == pytest.approx(np.degrees(0.25)) and best["score [-]"] == 3.0
    # the given poses' places come from best.json; the gain is (score - best) / score
    assert rows["far_rotated"]["yaw [deg]"] == pytest.approx(30.0)
    assert rows["far_rotated"]["x [mm]"] == pytest.approx(1900.0)
    assert rows["near"]["best is lower by [%]"] == pytest.approx(25.0)
    assert rows["far_rotated"]["best is lower by [%]"] == pytest.approx(40.0)
    items = dict(next(s for s in secs if s["type"] == "summary")["items"])
    assert items["improvement over the best given pose [%]"] == pytest.approx(25.0)
    assert items["best given pose, its score [-]"] == "near, 4.0000"
    # the history: the running best falls to the best score; the skipped candidate is in the CSV only
    plot = next(s for s in secs if s["type"] == "plot")
    running = next(s for s in plot["series"] if s["style"] == "step")
    assert running["y"] == [4.0, 4.0, 4.0, 3.5, 3.5, 3.0]
    assert sum(len(s["x"]) for s in plot["series"] if s["style"] == "points") == 6
    hist = next(s for s in secs if s.get("id") == "history")
    assert len(hist["rows"]) == 6 and "c_skip" not in {r[1] for r in hist["rows"]}
    heat = next(s for s in secs if s["type"] == "image")
    assert client.get(heat["url"], headers=HEADERS).content[:4] == b"\x89PNG" and "compliance" in heat["note"]
    names = {f["name"] for f in next(s for s in secs if s["type"] == "files")["files"]}
    assert names == {f"out/{n}" for n in ("best.json", "report.md", "history.csv", "heatmap.png", "summary.json")}


def test_new_kinds_keep_the_access_rules(client):
    store, jobs = client.app.state.store, client.app.state.manager.jobs_dir
    circle, search = _circle_job(store, jobs), _placement_job(store, jobs)
    for prefix, job_id, other in (("/circles", circle, search), ("/placement-searches", search, circle)):
        r = client.get(f"{prefix}/{job_id}/view")
        assert r.status_code == 401 and 'id="login-form"' in r.text and job_id not in r.text
        assert client.get(f"{prefix}/{job_id}/view/data").status_code == 401
        assert client.get(f"{prefix}/{job_id}/view/files/out/summary.json").status_code == 401
        assert client.post(f"{prefix}/{job_id}/view-link").status_code == 401
        link = client.post(f"{prefix}/{job_id}/view-link", headers=HEADERS).json()
        assert link["url"].startswith(f"{prefix}/{job_id}/view?token=")
        assert client.get(link["url"]).status_code == 200
        assert client.get(f"{prefix}/{job_id}/view/data", params={"token": link["token"]}).status_code == 200
        # the link opens this job only; the other kind's job is not found under this prefix
        assert client.get(f"{prefix}/{other}/view/data", params={"token": link["token"]}).status_code == 401
        assert client.get(f"{prefix}/{other}/view", headers=HEADERS).status_code == 404
        assert client.get(f"{prefix}/{'e' * 32}/view", headers=HEADERS).status_code == 404


def test_unfinished_and_damaged_jobs(client):
    from service.jobs import JobKind, owner_of

    store, jobs = client.app.state.store, client.app.state.manager.jobs_dir
    rec = store.create(JobKind.circle, {}, boot="test", owner=owner_of(KEY))
    r = client.get(f"/circles/{rec.id}/view", headers=HEADERS)
    assert r.status_code == 409 and "queued" in r.text and "Traceback" not in r.text
    job_id = _placement_job(store, jobs)
    (jobs / job_id / "out" / "best.json").write_text("{}")
    assert client.get(f"/placement-searches/{job_id}/view/data", headers=HEADERS).status_code == 409
    assert client.get(f"/placement-searches/{job_id}/view", headers=HEADERS).status_code == 409


# ---- the pages in Chromium ---------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def server(tmp_path_factory):
    d = tmp_path_factory.mktemp("view-kinds") / "data"
    srv = Server(data_dir=d, env=server_env(d)).start()
    try:
        yield srv
    finally:
        srv.stop()


def _open(browser, srv, prefix, job_id, shot=None):
    with srv.client() as c:
        link = c.post(f"{prefix}/{job_id}/view-link").json()
    page, problems = watched_page(browser)
    # three.js is for a page with a 3D part only: these pages must not download it
    page.on("request", lambda r: problems.append(f"fetched {r.url}") if "/vendor/three/" in r.url else None)
    page.goto(srv.url + link["url"])
    page.wait_for_function("() => window.greybenchView && window.greybenchView.ready", timeout=60_000)
    page.wait_for_function("() => [...document.images].every(i => i.complete && i.naturalWidth > 0)", timeout=30_000)
    if shot:
        # GREYBENCH_VIEW_SHOTS=<folder> keeps the screenshots to look at
        folder = os.environ.get("GREYBENCH_VIEW_SHOTS")
        page.screenshot(path=str(Path(folder) / shot.name if folder else shot), full_page=True)
    return page, problems


def test_circle_page_in_chromium(server, browser, tmp_path):
    from service.jobs import JobStore

    job_id = _circle_job(JobStore(server.data_dir / "jobs.sqlite"), server.data_dir / "jobs")
    page, problems = _open(browser, server, "/circles", job_id, tmp_path / "circle.png")
    summary = dict(r.split("\t") for r in page.locator("section.summary tr").all_inner_texts())
    # one format per row with its unit: µm to 0.1, whole values keep their decimals (50.000 mm, not 50)
    assert summary["roundness (circular deviation G, ISO 230-4) [µm]"] == f"{ROUNDNESS_UM:.1f}"
    assert summary["radius error (least-squares radius - nominal) [µm]"] in ("-3.2", "-3.3")   # -3.25 to 0.1
    assert summary["largest lost motion, step of the settled trace [µm]"] == "6.0"
    assert summary["radius [mm]"] == "50.000" and summary["feed [mm/min]"] == "2000.0"
    assert summary["friction scale [-]"] == "1.00" and summary["centre offset, in-plane axes [µm]"] == "0.5, -0.2"
    spikes = [r.split("\t") for r in page.locator("table[data-id='spikes'] tbody tr").all_inner_texts()]
    assert spikes == [[f"{a:.1f}", j, f"{sp:.1f}", f"{lm:.1f}", f"{h:.1f}"] for a, j, sp, lm, h in REVERSAL_ROWS]
    assert page.locator("section.polar svg polyline").count() == 1
    assert page.locator("section.polar svg text.mark").all_text_contents() == [
        "A1+A6 spike +1.5 µm, lost motion +6.0 µm", "A2 spike -3.0 µm, lost motion -1.0 µm"]
    # every label inside the drawing (the left one was cut off), and the polar plot drawn once (no PNG copy)
    outside = page.evaluate("""() => { const svg = document.querySelector('section.polar svg').getBoundingClientRect();
        return [...document.querySelectorAll('section.polar svg text')].map(t => t.getBoundingClientRect())
          .filter(b => b.left < svg.left - 0.5 || b.right > svg.right + 0.5 || b.top < svg.top - 0.5
                       || b.bottom > svg.bottom + 0.5).length; }""")
    assert outside == 0
    assert page.locator("section.image img").count() == 0 and page.locator("svg.polar").count() == 1
    assert page.locator("ul.files a").count() == 3
    assert not problems, problems
    page.close()


def test_placement_page_in_chromium(server, browser, tmp_path):
    from service.jobs import JobStore

    job_id = _placement_job(JobStore(server.data_dir / "jobs.sqlite"), server.data_dir / "jobs")
    page, problems = _open(browser, server, "/placement-searches", job_id, tmp_path / "placement.png")
    rows = [r.split("\t") for r in page.locator("table[data-id='poses'] tbody tr").all_inner_texts()]
    assert [r[0] for r in rows] == ["optimised", "near", "far_rotated"]
    assert rows[0][8] == "3.0000" and rows[1][8] == "4.0000" and rows[1][10] == "25.00" and rows[2][10] == "40.00"
    assert page.locator("table[data-id='poses'] tr.highlight").count() == 1
    assert page.locator("svg.plot circle.pt").count() == 6
    assert page.locator("table[data-id='history'] tbody tr").count() == 6
    assert page.evaluate("document.querySelector('section.image img').naturalWidth") == 80
    assert page.locator("ul.files a").count() == 5
    assert not problems, problems
    page.close()


def test_key_entered_once_opens_the_circle_page(server, browser):
    from service.jobs import JobStore
    from tests.service.conftest import KEY

    job_id = _circle_job(JobStore(server.data_dir / "jobs.sqlite"), server.data_dir / "jobs")
    page = browser.new_page()
    page.goto(f"{server.url}/circles/{job_id}/view")
    page.wait_for_selector("#login:not([hidden])")
    assert page.locator("section.summary").count() == 0             # no data before a key
    page.fill("#login-key", KEY)
    page.click("#login-form button")
    page.wait_for_function("() => window.greybenchView && window.greybenchView.ready", timeout=60_000)
    assert "token=" in page.url and f"/circles/{job_id}/view" in page.url
    assert page.locator("table[data-id='spikes'] tbody tr").count() == len(REVERSAL_ROWS)
    page.close()


# ---- real jobs (slow: a circle simulation and a short placement search) --------------------------------------
@pytest.mark.slow
def test_pages_of_real_jobs(server, browser):
    """The pages read what real jobs write: the numbers shown are the jobs' results."""
    import time

    with server.client() as c:
        circle = c.post("/circles", json={"pose_set": "iso160", "pose": "near", "options": {"radius_mm": 50},
                                          "friction": ROBOT_FRICTION})
        search = c.post("/placement-searches", json={"program": "iso160", "pose_set": "iso160", "options": {
            "budget_s": 600, "spacing_mm": 1.0, "max_simulations": 4}})
        assert circle.status_code == 202 and search.status_code == 202, (circle.text, search.text)
        done = {}
        deadline = time.time() + 1500
        for prefix, r in (("/circles", circle), ("/placement-searches", search)):
            job = r.json()["id"]
            while (st := c.get(f"{prefix}/{job}").json())["state"] not in ("succeeded", "failed", "cancelled"):
                assert time.time() < deadline, st
                time.sleep(1)
            assert st["state"] == "succeeded", st
            done[prefix] = st
    res = done["/circles"]["result"]
    page, problems = _open(browser, server, "/circles", done["/circles"]["id"])
    summary = dict(r.split("\t") for r in page.locator("section.summary tr").all_inner_texts())
    assert float(summary["roundness (circular deviation G, ISO 230-4) [µm]"]) == pytest.approx(res["roundness_um"],
                                                                                                abs=5e-4)
    rows = [r.split("\t") for r in page.locator("table[data-id='spikes'] tbody tr").all_inner_texts()]
    from service.view import reversal_groups

    assert [(float(a), j, float(sp), float(lm), float(h)) for a, j, sp, lm, h in rows] == [
        (pytest.approx(g[0]["angle_deg"], abs=0.05), ", ".join(s["joint"] for s in g),
         pytest.approx(g[0]["spike_um"], abs=0.005), pytest.approx(g[0]["lost_motion_um"], abs=0.005),
         pytest.approx(g[0]["height_um"], abs=0.005)) for g in reversal_groups(res["reversal_spikes"])]
    assert not problems, problems
    page.close()
    res = done["/placement-searches"]["result"]
    page, problems = _open(browser, server, "/placement-searches", done["/placement-searches"]["id"])
    rows = [r.split("\t") for r in page.locator("table[data-id='poses'] tbody tr").all_inner_texts()]
    assert rows[0][0] == res["best"]["name"] and float(rows[0][8]) == pytest.approx(res["best"]["score"], abs=5e-5)
    assert {r[0]: float(r[8]) for r in rows[1:]} == {g["name"]: pytest.approx(g["score"], abs=5e-5)
                                                      for g in res["given"]}
    best_given = next(r for r in rows[1:] if r[0] == res["best_given"])
    assert float(best_given[10]) == pytest.approx(100 * res["improvement"], abs=5e-3)
    assert page.locator("svg.plot circle.pt").count() == res["candidates"]["simulated"]
    assert not problems, problems
    page.close()
