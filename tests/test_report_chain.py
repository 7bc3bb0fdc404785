"""report.html as an engineer's instrument: the signal chain per train in its cab system's own
terms (ALSN's letters, ALSU's code numbers, TVM's steps), each receiver error with its cause,
a provenance block, an interrupted run's verdict qualified, and a page that works offline."""
import json
import re

import numpy as np
import pytest

from helpers import REPO, railcosim


def _chains(run):
    from orchestrator.reports import chain_view
    from orchestrator.reports.report import read_results

    summary = json.loads((run / "summary.json").read_text())
    metadata = json.loads((run / "metadata.json").read_text())
    chains, missing = chain_view.chains(read_results(run), summary, metadata["components"])
    assert not missing, missing
    return chains, summary, metadata


def _run(tmp_path, system, stop_s):
    run = tmp_path / system
    code, _, stderr = railcosim("run", system, "--output", run, "--no-build", "--in-process", "--stop-time", stop_s)
    assert code == 0, stderr
    return run


def test_alsn_chain_in_letters_and_its_errors_at_the_joints(tmp_path, product_fmus):
    """free_run to 300 s: the code sent under the coils is З from the first circuit on, what the
    receiver shows is in ALSN's letters, and the receiver's error at 278.3 s (the coils entered
    circuit 3 at 277.1 s) is put down to that joint, not to noise."""
    from orchestrator.reports.chain_view import ASPECT_COLOURS
    from fmus.signalling import aspects as sig

    chains, summary, _ = _chains(_run(tmp_path, "free_run", 300))
    (chain,) = chains
    assert chain.cab.name == "ALSN" and chain.train == "train"
    assert {s.label for s in chain.sent if s.t0_s > 1.0} == {"З"}
    assert {s.colour for s in chain.sent if s.t0_s > 1.0} == {ASPECT_COLOURS[sig.GREEN]}
    assert {s.label for s in chain.shown} <= {"Б", "К", "КЖ", "Ж", "З"} and "З" in {s.label for s in chain.shown}
    counted = summary["receivers"][0]["code_errors"]
    assert sum(e.count for e in chain.errors) == counted > 0
    assert all(e.cause == "section change" for e in chain.errors), chain.errors


def test_tvm430_chain_in_speed_steps_and_its_errors_at_the_circuit_boundaries(tmp_path, product_fmus):
    """TVM-430 to 120 s: every code sent and shown is a step pair ``300→300`` in the steps'
    colours, not the ALSN aspect colours; the errors its receiver counts come where the coils
    cross from one UM71 circuit into the next."""
    from orchestrator.reports.chain_view import STEP_COLOURS

    chains, summary, _ = _chains(_run(tmp_path, "tvm430", 120))
    (chain,) = chains
    on_line = [s for s in chain.sent if s.label not in ("off the circuits", "no code")]
    assert on_line and all(re.fullmatch(r"\d+→\d+", s.label) for s in on_line)
    assert {s.colour for s in on_line} <= set(STEP_COLOURS)
    assert any(re.fullmatch(r"300→\d+", s.label) for s in chain.shown)
    assert sum(e.count for e in chain.errors) == summary["receivers"][0]["code_errors"] > 0
    assert all(e.cause == "section change" for e in chain.errors), chain.errors


def test_alsu_chain_in_code_numbers(tmp_path, product_fmus):
    """ALSU to 250 s: the codes are named by number (code 9 on the open line, code 6 after the
    4-aspect block's yellow), sent, decoded and shown alike once the receiver has the code."""
    chains, _, _ = _chains(_run(tmp_path, "alsu", 250))
    (chain,) = chains
    sent = [s.label for s in chain.sent if s.label.startswith("code ")]
    assert "code 9" in sent and "code 6" in sent
    shown = {s.label for s in chain.shown}
    assert {"code 9", "code 6"} <= shown


def test_each_receiver_error_is_explained_by_what_happened_under_the_coils():
    from orchestrator.reports.chain_view import explain_errors

    time = np.round(np.arange(0.0, 100.0, 0.1), 1)
    keys = np.zeros((len(time), 2), dtype=int)
    keys[:, 0] = np.where(time < 30.0, 1, np.where(time < 70.0, 2, 3))     # circuits 1, 2, 3
    keys[:, 1] = np.where((time >= 50.0) & (time < 60.0), 2, 4)            # the code sent drops to КЖ at 50 s
    keys[(time >= 80.0) & (time < 85.0), 1] = 0                             # no code in circuit 3 at 80–85 s
    errors = np.zeros(len(time))
    for t in (1.0, 31.0, 51.0, 69.5, 82.0, 95.0):
        errors[time >= t] += 1
    found = explain_errors(time, errors, keys, np.zeros(len(time)), latency_s=2.0)
    # as in a real run, the coils come onto the line from no circuit at the first row: that is
    # no crossing, and an error just after it is the receiver acquiring the code
    keys[0, 0] = 0
    assert explain_errors(time, errors, keys, np.zeros(len(time)), latency_s=2.0)[0].cause == "acquisition"
    assert [(e.t_s, e.cause) for e in found] == [
        (1.0, "acquisition"), (31.0, "section change"), (51.0, "code change"), (69.5, "section change"),
        (82.0, "no code"), (95.0, "steady code")]
    assert "circuit 2 at 30.0 s" in found[1].explanation and "circuit 3" in found[3].explanation


def _interrupted_summary():
    return {"system": "s", "sim_time_s": 42.0, "realtime_factor": 5.0, "completed": False, "interrupted": "SIGINT",
            "trains": [], "receivers": [{"receiver": "rx", "system": "ALSN", "train": "t", "wrong_side_failures": 0,
                                         "unsafe_indications": 0}]}


def test_an_interrupted_runs_verdict_says_over_which_time_it_holds(tmp_path):
    from orchestrator.reports.report import verdict_table, write_html

    summary = _interrupted_summary()
    write_html(tmp_path / "report.html", summary, [], {"stop_time_s": 1100.0})
    page = (tmp_path / "report.html").read_text()
    assert 'class="interrupted"' in page and "interrupted by SIGINT at 42.0 s of 1100.0 s" in page
    assert "safe (signals passed at danger 0, wrong-side failures 0, unsafe indications 0) over 0–42.0 s only" in page
    assert "over 0–42.0 s only (the run did not complete)" in verdict_table(summary)


#: what a page may not do to stay offline: load a script, a style sheet, an image or a frame
#: from anywhere, or use a model that fetches (map tiles, Google Maps, a TeX renderer)
FETCHING = re.compile(r"<(script|link|img|iframe)\b[^>]*\b(src|href)\s*=\s*[\"']?(https?:)?//", re.I)
FETCHING_MODELS = ("GMapPlot", "TileSource", "TeX", "MathML", "ImageURL", "GeoJSONDataSource", "AjaxDataSource")


def check_offline(page: str, limit_bytes: int) -> None:
    assert len(page.encode()) < limit_bytes
    assert not FETCHING.search(page), FETCHING.search(page)
    assert "url(http" not in page.replace(" ", "") and "@import" not in page
    documents = bokeh_documents(page)
    assert documents, "no Bokeh document embedded"
    for document in documents:
        kinds = set(re.findall(r'"name": "([A-Za-z0-9_]+)"', document))
        assert kinds and not {k for k in kinds for bad in FETCHING_MODELS if bad in k}, kinds
    return "\n".join(documents)


def bokeh_documents(page: str) -> list:
    """The Bokeh documents embedded in a page, as JSON text: each is a JavaScript string literal
    (ASCII, escaped as such) holding the document's JSON."""
    return [json.dumps(json.loads(literal.encode().decode("unicode_escape")), ensure_ascii=False)
            for literal in re.findall(r"const docs_json = '(.*?)';", page, re.S)]


def test_report_html_is_one_offline_page_with_the_chain_and_its_provenance(tmp_path, product_fmus):
    """free_run to 300 s: report.html holds the BokehJS it needs inline (no request anywhere, under
    5 MB), the chain figure and the speed figure of the train, the time–distance figure, a line
    telling how to capture the coil EMF, and a provenance block naming this railcosim, the system
    and its hash, the parameters set and the date."""
    from orchestrator.provenance import content_hash, railcosim_version, source_revision

    run = tmp_path / "run"
    code, _, stderr = railcosim("run", "free_run", "--output", run, "--no-build", "--in-process", "--stop-time", "300",
                                "--set", "ato.cab_signal=ALSN")
    assert code == 0, stderr
    code, _, stderr = railcosim("report", run)
    assert code == 0, stderr
    page = (run / "report.html").read_text(encoding="utf-8")
    figures = check_offline(page, 5_000_000)
    metadata = json.loads((run / "metadata.json").read_text())
    assert metadata["railcosim_version"] == railcosim_version() and metadata["overrides"]
    assert metadata["railcosim_source"] == source_revision()          # this checkout's commit
    assert metadata["data_files_sha256"] == {}        # free_run names no data file: the bundled ones
    assert metadata["system_sha256"] == content_hash(REPO / "ssp" / "free_run")
    provenance = re.search(r'<table id="provenance">(.*?)</table>', page, re.S).group(1)
    for shown in (railcosim_version(), metadata["system_sha256"], metadata["date_utc"],
                  *(f"{k} = {v}" for k, v in metadata["overrides"].items())):
        assert shown in provenance, shown
    assert "yes: 300.0 s simulated" in provenance
    for title in ("train train: ALSN chain (receiver rx)", "train train: speed and the ATP", "time–distance",
                  "code sent under the coils", "З"):
        assert title in figures, title
    assert "railcosim run free_run --capture rail.e_coil[1]@" in page


def test_the_offline_check_refuses_a_page_that_loads_bokeh_from_its_cdn():
    from bokeh.embed import file_html
    from bokeh.plotting import figure
    from bokeh.resources import CDN

    with pytest.raises(AssertionError):
        check_offline(file_html(figure(), CDN), 5_000_000)


def test_wrong_side_unsafe_and_scenario_events_on_the_chain_are_marked():
    """The verdicts' episodes of a receiver and the scenario's events on its chain's components
    are the chain's marks; an event on another train's components is not."""
    from orchestrator.reports.chain_view import episodes

    receiver = {"receiver": "rx", "rail": "rail", "coder": "coder", "train": "train",
                "wrong_side_events": [{"t": 310.0, "section": 4, "code_sent": 2}],
                "unsafe_events": [{"t": 120.5, "section": 2, "free_blocks_allowed": 0, "aspect_shown": 4}]}
    events = [{"t": 100.0, "model": "coder", "variable": "transmitter_failed[3]", "action": "set", "value": True},
              {"t": 200.0, "model": "rx2", "variable": "noise_v", "action": "set", "value": 0.5}]
    found = episodes(receiver, events)
    assert [(e.t_s, e.kind) for e in found] == [(100.0, "event"), (120.5, "unsafe"), (310.0, "wrong-side")]
    assert "circuit 4, code sent 2" in found[2].text and "aspect shown green" in found[1].text
    assert "coder.transmitter_failed[3] = True" in found[0].text


def test_a_code_whose_current_does_not_reach_the_first_axle_is_told_apart():
    """A pulsed KPT code (the current zero between pulses) arrives; a code the coder sends into a
    circuit whose current the first axle never sees (a train ahead shunts it) does not, and the
    receiver's error then is put down to that, not to noise."""
    from orchestrator.reports.chain_view import code_arrives, explain_errors

    time = np.round(np.arange(0.0, 60.0, 0.1), 1)
    pulsed = np.where((time % 1.6) < 0.6, 3.0, 0.0)                 # 3 A pulses, gaps of 1 s
    current = np.where(time < 30.0, 0.0, pulsed)                    # nothing reaches the axle before 30 s
    sent = np.ones(len(time), dtype=bool)
    arrives = code_arrives(time, current, sent, reference_a=3.0)
    assert not arrives[time < 28.0].any() and arrives[time >= 30.0].all()
    assert code_arrives(time, np.full(len(time), np.nan), sent, 3.0).all()     # not recorded: not judged
    assert code_arrives(time, current, sent, None).all()                      # no reference: not judged
    keys = np.column_stack((np.ones(len(time), dtype=int), np.full(len(time), 4), arrives))
    errors = (time >= 20.0).astype(float)
    (error,) = explain_errors(time, errors, keys, np.zeros(len(time)), latency_s=4.5)
    assert error.cause == "no code" and "does not reach the first axle" in error.explanation


@pytest.mark.parametrize("system, code, label", [("ALSN", 3, "Ж"), ("ALSN", 2, "КЖ"), ("ALSU", 6, "code 6"),
                                                 ("ALS-EN", 15, "free 6, 160 km/h")])
def test_a_code_reads_the_same_sent_and_decoded(system, code, label):
    """The coder's code_tx and the receiver's code are one numbering: the same value is named
    alike on the sent and the decoded row (ALS-EN's KLUB register 15 is 6 free blocks at 160,
    not the command 15)."""
    from fmus.signalling import cab_systems
    from orchestrator.reports.chain_view import ChainReader

    reader = ChainReader(cab_systems.lookup(system), {"system": system}, top_kmh=160.0)
    assert reader.sent((2, code, 1))[0] == label and reader.sent((2, -1, 1))[0] == "not recorded"
    assert reader.decoded((1, code))[0] == label
    assert reader.decoded((0, code))[0] == "none"


def test_the_follower_under_a_code_its_leader_shunts_is_shown_so(tmp_path, product_fmus):
    """following to 300 s: the follower (slot 2 of the rail line) stands behind its leader in
    circuit 1 for its first 180 s: the codes sent there never reach its first axle, and the
    page says so (hatched, ✕) for those seconds only — although that is more than half of its
    own rows, the reference is the rail line's (the leader's) current."""
    from orchestrator.reports.chain_view import NOT_ARRIVING

    chains, summary, _ = _chains(_run(tmp_path, "following", 300))
    follower = next(c for c in chains if c.train == "follower")
    assert follower.slot == 2 and follower.rail == "rail"
    hatched = [s for s in follower.sent if s.hatched]
    assert hatched and all(s.label.endswith(NOT_ARRIVING) for s in hatched)
    assert hatched[0].t0_s < 5.0 and 150.0 < hatched[-1].t1_s < 190.0
    assert not any(s.hatched for s in next(c for c in chains if c.train == "leader").sent)


@pytest.mark.parametrize("record", [(), ("rail.coil_section[1]", "coder.code_tx[1]", "coder.code_tx[3]", "rx.aspect",
                                         "rx.code", "train.x")], ids=["one row", "few columns"])
def test_the_report_of_a_run_with_little_in_it_is_a_page(tmp_path, product_fmus, record):
    """A run of one output row, or one recorded with a few --record columns: report.html is
    written with what there is (a circuit whose code_tx was not recorded says so), no traceback."""
    run = tmp_path / "run"
    options = [x for column in record for x in ("--record", column)]
    code, _, stderr = railcosim("run", "free_run", "--output", run, "--no-build", "--in-process", "--stop-time",
                                "0.05" if not record else "300", *options)
    assert code == 0, stderr
    code, _, stderr = railcosim("report", run)
    assert code == 0 and "Traceback" not in stderr, stderr
    page = (run / "report.html").read_text(encoding="utf-8")
    assert "<h2>The signal chain over time</h2>" in page
    if record:
        assert "not recorded" in "\n".join(bokeh_documents(page))
        assert "the run did not record its speed (train.v)" in page


def test_a_run_whose_metadata_names_no_components_reads_its_system_from_the_summary():
    """TVM-430 codes under a run's summary alone (metadata.json without components): read as
    TVM-430 steps, not as ALSN aspects."""
    from orchestrator.reports.chain_view import chains

    time = np.round(np.arange(0.0, 10.0, 0.1), 1)
    from fmus.signalling import cab_systems

    tvm = cab_systems.lookup("TVM430").system()
    word = next(c for c in (98398806, 85029484) if tvm.command_of_code(c) is not None)
    results = {"time": time, "rail.coil_section[1]": np.ones(len(time)), "coder.code_tx[1]": np.full(len(time), word),
               "rx.aspect": np.full(len(time), 4.0), "rx.code": np.full(len(time), float(word)),
               "rx.code_valid": np.ones(len(time))}
    summary = {"receivers": [{"receiver": "rx", "train": "train", "system": "TVM430", "rail": "rail",
                              "coder": "coder", "slot": 1, "latency_s": 3.5}]}
    (chain,), missing = chains(results, summary, {})
    assert not missing and chain.cab.name == "TVM430"
    assert re.fullmatch(r"\d+→\d+", chain.sent[0].label) and chain.sent[0].label == chain.decoded[0].label


def test_the_data_files_a_run_names_are_hashed(tmp_path):
    """A line or timetable file outside the system folder is part of what was run: metadata.json
    gives its SHA-256, so an edited copy is told apart."""
    from orchestrator.provenance import content_hash, data_file_hashes

    line = tmp_path / "line.json"
    line.write_text('{"name": "x"}')
    hashes = data_file_hashes({"ato": {"line_file": str(line), "v_max": 40.0}, "train": {"line_file": str(line)}})
    assert hashes == {str(line): content_hash(line)}
    line.write_text('{"name": "y"}')
    assert data_file_hashes({"ato": {"line_file": str(line)}})[str(line)] != hashes[str(line)]
