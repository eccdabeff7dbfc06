"""The bad inputs of issue 19, each through the command a user ran: a one-line error (exit 1,
nothing written) or a correct result, never a wrong path with exit 0 or a traceback.

Recordings are tiny (``recording_faults.arm_scan``: a moving two-link arm, 32 x 24 images), so
each case costs a fraction of a second; the disk-full cases use RLIMIT_FSIZE (SIGXFSZ ignored:
a write past the limit fails with EFBIG, as on a full disk, without root or a small tmpfs).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from click.testing import CliRunner
from helpers import one_line_error, synthetic_scan, under_file_size_limit, write_scan
from recording_faults import arm_scan

from scrapcut_cli.cli import cli

FIXTURE = Path(__file__).resolve().parents[1] / "fixtures" / "sim_cylinder_small.mcap"


def run(*args: object) -> object:
    return CliRunner().invoke(cli, [str(a) for a in args])


# --------------------------------------------------------------------------- wrong frames, exit 0


@pytest.mark.parametrize(
    ("fault", "message"),
    [
        ({"drop_link": "link2"}, r"the TF tree is split: image frame 'cam' hangs from 'link2'"),
        ({"with_tf": False}, r"no time-varying link \(only /tf_static\) but the images move"),
        ({"same_stamp": True}, r"4 of 4 colour images .* share a header stamp"),
        ({"nan_intrinsics": True}, r"intrinsics must be finite, got fx=nan"),
    ],
)
def test_a_recording_that_cannot_be_posed_is_refused(
    tmp_path: Path, fault: dict[str, object], message: str
) -> None:
    import re

    rec = arm_scan(tmp_path / "scan.mcap", **fault)  # type: ignore[arg-type]
    for args in (["info", rec], ["fit", rec, "-o", tmp_path / "path.json"]):
        line = one_line_error(run(*args))
        assert re.search(message, line), line
    assert sorted(p.name for p in tmp_path.iterdir()) == ["scan.mcap"]


def test_the_intact_arm_scan_is_posed_in_its_base(tmp_path: Path) -> None:
    result = run("info", arm_scan(tmp_path / "scan.mcap"), "--json")
    assert result.exit_code == 0, result.output
    info = json.loads(result.stdout)
    assert info["base_frame"] == "base" and info["frames"]["usable"] == 4


def test_a_base_frame_that_moves_is_refused_and_names_the_fixed_one(tmp_path: Path) -> None:
    rec = arm_scan(tmp_path / "scan.mcap")
    line = one_line_error(run("info", rec, "--base-frame", "link2"))
    assert "--base-frame link2 moves during the scan" in line
    assert "pass the robot's fixed base (base)" in line


def test_a_few_repeated_stamps_are_skipped_and_counted(tmp_path: Path) -> None:
    """A driver re-publishing a frame now and then: the copy is skipped, not fatal."""
    rec = arm_scan(tmp_path / "scan.mcap", frames=12, repeat_frame=5)
    result = run("info", rec, "--json")
    assert result.exit_code == 0, result.output
    frames = json.loads(result.stdout)["frames"]
    assert frames["usable"] == 11 and frames["skip_reasons"] == {"duplicate_stamp": 1}


def test_an_image_all_in_the_paints_colour_is_no_stroke() -> None:
    from perception_scenes import cylinder_top_line, render_cylinder, small_camera, top_view

    from scrapcut_cli.config import PerceptionConfig
    from scrapcut_cli.errors import PerceptionError
    from scrapcut_cli.perception.cloud import PerceptionTally, process_frame
    from scrapcut_cli.perception.paint import PAINT_PRESETS

    orange = PAINT_PRESETS["orange"]
    frame = render_cylinder(small_camera(), top_view(0.02), cylinder_top_line())
    assert process_frame(frame, orange.hsv, PerceptionConfig()).skip_reason is None
    frame.color[:] = orange.rgb  # paint over the lens, an orange wall
    clouds = process_frame(frame, orange.hsv, PerceptionConfig())
    assert clouds.skip_reason == "paint_fills_image" and len(clouds.paint_base) == 0
    tally = PerceptionTally(orange.hsv)
    tally.add(clouds, frame.color)
    with pytest.raises(PerceptionError, match=r"covers most of the image.*--paint or --hsv"):
        tally.raise_if_no_paint()
    # 1.0 switches the check off: the wall is then one blob far wider than a stroke, kept apart
    # as other paint (reported, never cut) and named as such.
    everything = process_frame(frame, orange.hsv, PerceptionConfig(max_paint_share=1.0))
    assert everything.skip_reason == "paint_too_wide" and len(everything.paint_base) == 0
    tally = PerceptionTally(orange.hsv)
    tally.add(everything, frame.color)
    with pytest.raises(PerceptionError, match=r"wider than a stroke"):
        tally.raise_if_no_paint()


def test_eval_refuses_a_path_in_another_frame_than_its_reference(tmp_path: Path) -> None:
    rec = tmp_path / "scan.mcap"
    write_scan(rec, synthetic_scan(), "mcap")  # its reference is in panda_link0
    points = [[0.4, 0.0, 0.0], [0.5, 0.05, 0.0], [0.6, 0.1, 0.0]]
    path = tmp_path / "path.json"
    for frame, ok in (("panda_link4", False), ("panda_link0", True)):
        data = {
            "schema": "scrapcut.path/v1",
            "source": {"path": str(rec)},
            "frame_id": frame,
            "units": "m",
            "method": {"name": "nurbs", "params": {}},
            "curve": {"points": points},
            "path": {"standoff_m": 0.008, "spacing_m": 0.005, "setpoints": []},
        }
        path.write_text(json.dumps(data))
        result = run("eval", path, "--format", "json")
        if ok:
            assert result.exit_code == 0, result.output
        else:
            line = one_line_error(result)
            assert "in frame 'panda_link4' but the reference" in line
            assert "is in 'panda_link0'" in line


# --------------------------------------------------------------------------- damaged inputs


def test_what_a_recorder_killed_at_once_leaves_is_one_line(tmp_path: Path) -> None:
    stub = tmp_path / "scan.mcap"
    stub.write_bytes(b"\x89MCAP0\r\n")
    assert "truncated" in one_line_error(run("info", stub))
    assert "nothing could be salvaged" in one_line_error(run("info", stub, "--salvage"))


def test_a_named_pipe_as_recording_fails_at_once(tmp_path: Path) -> None:
    fifo = tmp_path / "scan.mcap"
    os.mkfifo(fifo)
    for command in ("info", "fit", "stitch", "filter", "convert"):
        args = [command, fifo]
        if command in ("fit", "stitch", "convert"):
            args += ["-o", tmp_path / {"fit": "p.json", "stitch": "c.ply"}.get(command, "c.bag")]
        assert "named pipe (FIFO)" in one_line_error(run(*args))  # returns: nothing read it


def test_link_loops_are_named_not_tracebacks(tmp_path: Path) -> None:
    loop = tmp_path / "loop.mcap"
    loop.symlink_to(loop)
    out = tmp_path / "out.json"
    out.symlink_to(out)
    assert "symbolic link" in one_line_error(run("fit", loop, "-o", tmp_path / "p.json"))
    assert "symbolic link loop" in one_line_error(run("fit", FIXTURE, "-o", out))
    assert "symbolic link loop" in one_line_error(run("eval", out))


def test_a_path_file_nested_100000_deep_is_one_line(tmp_path: Path) -> None:
    deep = tmp_path / "deep.json"
    deep.write_text("[" * 100_000 + "]" * 100_000)
    csv = tmp_path / "ref.csv"
    csv.write_text("x,y,z\n0,0,0\n0.1,0,0\n")
    assert "nested too deep" in one_line_error(run("eval", deep, "--reference", csv))


def test_reference_coordinates_of_1e300_are_refused(tmp_path: Path) -> None:
    csv = tmp_path / "ref.csv"
    csv.write_text("x,y,z\n0,0,0\n1e300,0,0\n")
    path = tmp_path / "p.json"
    path.write_text(
        json.dumps(
            {
                "schema": "scrapcut.path/v1",
                "source": {"path": None},
                "frame_id": "panda_link0",
                "units": "m",
                "method": {"name": "nurbs", "params": {}},
                "curve": {"points": [[0, 0, 0], [0.1, 0, 0]]},
                "path": {"standoff_m": 0.008, "spacing_m": 0.005, "setpoints": []},
            }
        )
    )
    line = one_line_error(run("eval", path, "--reference", csv))
    assert "beyond 1e+06 m (first: line 3)" in line


# --------------------------------------------------------------------------- outputs


def test_a_device_as_output_is_refused_before_any_work(tmp_path: Path) -> None:
    before = os.stat("/dev/null")
    line = one_line_error(run("fit", tmp_path / "missing.mcap", "-o", "/dev/null"))
    assert "/dev/null is a character device" in line  # named before the recording is read
    after = os.stat("/dev/null")
    assert (after.st_mode, after.st_rdev) == (before.st_mode, before.st_rdev)


def test_convert_refuses_a_name_its_format_cannot_have(tmp_path: Path) -> None:
    line = one_line_error(run("convert", FIXTURE, "--format", "mcap", "-o", tmp_path / "x.bag"))
    assert "an MCAP file must be named *.mcap" in line and "-o x.mcap" in line
    assert list(tmp_path.iterdir()) == []


def test_a_full_disk_is_one_line_and_no_file(tmp_path: Path) -> None:
    rec = arm_scan(tmp_path / "scan.mcap")
    out = tmp_path / "out"
    out.mkdir()

    def check() -> None:
        for args, name in (
            (["convert", rec, "-o", out / "scan.bag"], "scan.bag"),
            (["convert", rec, "-o", out / "copy.mcap"], "copy.mcap"),
        ):
            line = one_line_error(run(*args))
            assert line.endswith(f"File too large: {out / name}"), line

    under_file_size_limit(4096, check)
    assert list(out.iterdir()) == []


def test_stitch_and_filter_on_a_full_disk_commit_nothing(tmp_path: Path) -> None:
    """open3d's writer reports success on a full disk: the size its header promises is checked
    (the limit holds for the C library's writes too: it is the process's)."""
    from perception_scenes import (
        cylinder_top_line,
        render_cylinder,
        small_camera,
        top_view,
        write_scene_recording,
    )

    reference = cylinder_top_line()
    frames = [
        render_cylinder(small_camera(), top_view(x), reference, index=i)
        for i, x in enumerate((-0.05, 0.0, 0.05))
    ]
    rec = tmp_path / "scene.mcap"
    write_scene_recording(rec, frames, reference=reference)
    out = tmp_path / "out"

    def check() -> None:
        for args in (["stitch", rec, "-o", out / "cloud.ply"], ["filter", rec, "-o", out]):
            line = one_line_error(run(*args))
            assert "written incompletely (is the disk full?)" in line
            assert not out.exists() or list(out.iterdir()) == []
        # Python's own writes fail loudly (EFBIG here, ENOSPC on a full disk): named, one line.
        line = one_line_error(run("fit", rec, "-o", out / "path.json", "--parents"))
        assert line.endswith(f"File too large: {out / 'path.json'}"), line

    under_file_size_limit(8000, check)
    assert not out.exists() or list(out.iterdir()) == []
    assert sorted(p.name for p in tmp_path.iterdir() if p.name != "out") == ["scene.mcap"]


def test_numpy_warnings_do_not_reach_the_terminal(tmp_path: Path) -> None:
    (tmp_path / "warncmd.py").write_text(
        "import click, numpy as np\n"
        "@click.command('warn')\n"
        "def warn():\n"
        "    click.echo(str(np.log(np.zeros(1))[0]))\n"
    )
    script = (
        "import sys; sys.path.insert(0, sys.argv[1])\n"
        "from scrapcut_cli import cli\n"
        "cli.COMMANDS['warn'] = ('warncmd', 'warn', 'test')\n"
        "sys.argv = ['scrapcut', 'warn']\n"
        "cli.main()\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", script, str(tmp_path)], capture_output=True, text=True
    )
    assert done.returncode == 0 and done.stdout.strip() == "-inf"
    assert done.stderr == ""
