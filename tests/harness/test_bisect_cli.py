"""``ckesc bisect`` end to end in simulation (issue #37 item 3): each step a real ``ckesc run --firmware IMAGE``
of emulator images (:mod:`firmware_images`), the flaky image and the bench that keeps state played by a stand-in
flash tool (:mod:`sim_flash`); and its front door, which refuses a list it cannot bisect before any run."""

from __future__ import annotations

import json
import shlex
import sys
from pathlib import Path

import pytest
from firmware_images import FAULT, series

from ckesc.cli import build_parser, main
from ckesc.cli.bisect import run_args
from ckesc.reporting.exits import ExitStatus

SIM_FLASH = Path(__file__).with_name("sim_flash.py")
SECTION = "4.4.27"  # finds the series' fault in a few seconds of wall time per run


def bisect(capsys, tmp_path: Path, *args: str) -> tuple[int, list[str], dict]:
    status = main(["bisect", "--reports", str(tmp_path / "reports"), *args, SECTION])
    lines = capsys.readouterr().out.strip().splitlines()
    found = sorted((tmp_path / "reports").glob("*-bisect/bisect.json"))
    return status, lines, json.loads(found[-1].read_text()) if found else {}


def flash_cmd(*options: str) -> str:
    return shlex.join([sys.executable, str(SIM_FLASH), *options]) + " {image}"


@pytest.mark.timeout(600)
@pytest.mark.parametrize("count, bad_from, steps", [
    (8, 5, [4, 6, 5]),  # CI's: a good and a bad verdict, the canary at the end, in 4 runs
    pytest.param(32, 19, [16, 24, 20, 18, 19], marks=pytest.mark.slow),  # the history (benchmarks/bisection.py)
], ids=["8-images", "32-images"])
def test_a_series_with_a_fault_from_one_image_on_is_bisected_to_it(capsys, tmp_path, count, bad_from, steps):
    series(tmp_path, count, bad_from=bad_from)
    status, lines, doc = bisect(capsys, tmp_path, "--images", str(tmp_path / "images.txt"))
    assert status == ExitStatus.OK, lines
    assert lines[-3].endswith(f"build-{bad_from:02d}.toml") and lines[-3].startswith(f"first bad image: {bad_from}/{count}"), lines
    assert lines[-2].startswith(f"last good image: {bad_from - 1}/{count}"), lines
    assert doc["first_bad"]["number"] == bad_from and doc["bisect_steps"] == len(steps) and doc["runs"] == len(steps) + 1
    assert [s["number"] for s in doc["steps"]] == [*steps, 1] and doc["steps"][-1]["canary"]
    assert [s["verdict"] for s in doc["steps"]] == [*("bad" if n >= bad_from else "good" for n in steps), "good"]
    bad = next(s for s in doc["steps"] if s["verdict"] == "bad")["runs"][0]
    assert bad["outcome"] == "bad" and any("test_s4_4_27" in t for t in bad["failing"]) and len(bad["sha256"]) == 64
    assert (Path(bad["reports"]) / "results.json").is_file()
    assert sum(ln.startswith(("step ", "canary: ")) for ln in lines) == len(steps) + 1, "a line per step"


@pytest.mark.timeout(600)
def test_a_flaky_image_is_decided_by_retries_where_one_try_blames_it(capsys, tmp_path):
    """Image 4 of 8 (good; the fault comes with image 5) shows the fault one run in three, in its first run."""
    images = series(tmp_path, 8, bad_from=5)
    images[3].write_text(images[3].read_text().replace("faults = []", f'faults = ["{FAULT}"]'))
    status, lines, doc = bisect(capsys, tmp_path, "--images", str(tmp_path / "images.txt"), "--tries", "3",
                                "--flash-cmd", flash_cmd("--flaky", images[3].name))
    assert status == ExitStatus.OK and doc["first_bad"]["number"] == 5, lines
    flaky = doc["steps"][0]
    assert flaky["number"] == 4 and [r["outcome"] for r in flaky["runs"]] == ["bad", "good", "good"]
    assert "step 1: image 4/8" in lines[1] and "bad, good, good -> good" in lines[1]

    one_try = tmp_path / "again"
    one_try.mkdir()
    images = series(one_try, 8, bad_from=5)
    images[3].write_text(images[3].read_text().replace("faults = []", f'faults = ["{FAULT}"]'))
    status, lines, doc = bisect(capsys, one_try, "--images", str(one_try / "images.txt"),
                                "--flash-cmd", flash_cmd("--flaky", images[3].name))
    assert doc["first_bad"]["number"] == 4, "one try believes the flaky run: why --tries exists"


@pytest.mark.timeout(600)
def test_a_bench_that_keeps_state_is_caught_by_the_canary_not_blamed_on_a_build(capsys, tmp_path):
    series(tmp_path, 8, bad_from=5)
    status, lines, doc = bisect(capsys, tmp_path, "--images", str(tmp_path / "images.txt"),
                                "--flash-cmd", flash_cmd("--sticky"))
    assert status == ExitStatus.FAILED, lines
    assert doc["ending"] == "bench kept state" and doc["first_bad"] is None
    assert lines[-3].startswith("no first bad image: the known-good image 1 now fails"), lines
    assert doc["steps"][-1]["canary"] and doc["steps"][-1]["verdict"] == "bad"


def test_a_flash_that_fails_is_a_bench_error_and_stops_the_bisect(capsys, tmp_path):
    series(tmp_path, 8, bad_from=5)
    status, lines, doc = bisect(capsys, tmp_path, "--images", str(tmp_path / "images.txt"), "--tries", "3",
                                "--flash-cmd", "false {image}")
    assert status == ExitStatus.USAGE
    assert doc["runs"] == 1 and doc["ending"] == "bench error"
    assert "failed (exit status 1)" in lines[1], lines


# ------------------------------------------------------------------------------------------- the front door
def refused(capsys, *args: str) -> str:
    assert main(["bisect", *args, SECTION]) == ExitStatus.USAGE
    out = capsys.readouterr()
    assert out.out == "", "nothing ran"
    lines = out.err.strip().splitlines()
    assert len(lines) == 1, lines
    return lines[0]


def test_a_list_that_is_missing_short_or_names_a_missing_file_is_refused_in_one_line(capsys, tmp_path):
    assert "not readable" in refused(capsys, "--images", str(tmp_path / "nope.txt"))
    paths = series(tmp_path, 3)
    (tmp_path / "one.txt").write_text(f"{paths[0]}\n")
    assert "1 image(s)" in refused(capsys, "--images", str(tmp_path / "one.txt"))
    (tmp_path / "gap.txt").write_text(f"{paths[0]}\n# a comment\n\nbuild-99.toml\n")
    assert "build-99.toml is not a file" in refused(capsys, "--images", str(tmp_path / "gap.txt"))
    (tmp_path / "empty").mkdir()
    assert "holds no image" in refused(capsys, "--images", str(tmp_path / "empty"))


def test_a_directory_is_ordered_by_name_without_its_sidecars(tmp_path):
    from ckesc.bisect.steps import image_list

    for name in ("v2.bin", "v10.bin", "v1.bin", "v1.bin.toml", "firmware.toml"):
        (tmp_path / name).write_text("x")
    assert [p.name for p in image_list(str(tmp_path))] == ["v1.bin", "v10.bin", "v2.bin"]
    (tmp_path / "list.txt").write_text("v2.bin\nv1.bin\n")
    assert image_list(str(tmp_path / "list.txt")) == [tmp_path / "v2.bin", tmp_path / "v1.bin"], "relative to the list"


def test_the_bench_options_reach_each_steps_run_and_the_image_options_do_not():
    args = build_parser().parse_args(["bisect", "--images", "x", "--emulator-seed", "5", "--flash-cmd", "fl {image}",
                                      "--emulator-option", "report_timer=grid", "--allow-motor-spin", "4.4.27"])
    assert sorted(run_args(args)) == ["--allow-motor-spin", "--emulator-option=report_timer=grid", "--emulator-seed=5",
                                      "--flash-cmd=fl {image}"]
    with pytest.raises(SystemExit):
        build_parser().parse_args(["bisect", "--images", "x", "--firmware", "a.toml", "4.4.27"])


def test_a_directory_of_images_is_ordered_by_the_firmware_date_each_says_240_answers(tmp_path):
    """By the date each image's expectation says (a sidecar, an emulator image's own), as ckesc run proves it; by
    name where one says none."""
    from ckesc.bisect.steps import image_list

    for path in series(tmp_path, 3):  # build-01 oldest ... build-03 newest: named so that their names run backwards
        path.rename(path.with_name({"build-01.toml": "c.toml", "build-02.toml": "b.toml", "build-03.toml": "a.toml"}[path.name]))
    (tmp_path / "images.txt").unlink()
    assert [p.name for p in image_list(str(tmp_path))] == ["c.toml", "b.toml", "a.toml"]
    (tmp_path / "d.bin").write_text("an image nothing says the date of")
    assert [p.name for p in image_list(str(tmp_path))] == ["a.toml", "b.toml", "c.toml", "d.bin"], "one way: by name"


@pytest.mark.timeout(600)
def test_whatever_regressed_between_two_runs_is_what_each_step_runs(capsys, tmp_path):
    from ckesc.bisect.steps import regressed_tests

    pair = tmp_path / "pair"
    pair.mkdir()
    good, bad = series(pair, 2, bad_from=2)  # a release and the next, which regressed
    runs = []
    for image in (good, bad):
        main(["run", "-q", "--firmware", str(image), "--reports", str(tmp_path / image.stem), "--trace-format", "none",
              SECTION])
        runs.append(str(tmp_path / image.stem / "latest"))
    capsys.readouterr()
    regressed = regressed_tests(*runs)
    assert regressed and all("test_s4_4_27" in t for t in regressed)
    series(tmp_path, 4, bad_from=3)
    status = main(["bisect", "--reports", str(tmp_path / "reports"), "--images", str(tmp_path / "images.txt"),
                   "--regressed", *runs])
    lines = capsys.readouterr().out.strip().splitlines()
    assert status == ExitStatus.OK and lines[-3].startswith("first bad image: 3/4"), lines
    assert main(["bisect", "--images", str(tmp_path / "images.txt"), "--regressed", runs[0], runs[0]]) == ExitStatus.USAGE
    assert "no test regressed" in capsys.readouterr().err
    assert main(["bisect", "--images", str(tmp_path / "images.txt"), "--regressed", *runs, SECTION]) == ExitStatus.USAGE
    assert "one of the two" in capsys.readouterr().err
