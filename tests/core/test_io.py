"""The one safe writer, the overwrite policy and path confinement (``weather_gym.core._io``)."""

from __future__ import annotations

import os
import stat

import numpy as np
import pytest

from weather_gym.core._figures import save_figure
from weather_gym.core._io import (
    atomic_file,
    atomic_path,
    atomic_write,
    atomic_write_json,
    check_output,
    derived_outputs_replaceable,
    resolve_inside,
    write_image,
)
from weather_gym.core.errors import InputError, OutputExistsError, OutputPathError, OutsideRootError


def _names(folder):
    return sorted(p.name for p in folder.iterdir())


def test_new_file_is_written_and_an_existing_one_refused_unless_overwrite(tmp_path):
    p = tmp_path / "out.txt"
    atomic_write(p, "one")
    with pytest.raises(OutputExistsError, match="already exists; pass --overwrite"):
        atomic_write(p, "two")
    assert p.read_text() == "one" and _names(tmp_path) == ["out.txt"]
    atomic_write(p, b"three", overwrite=True)
    assert p.read_text() == "three" and _names(tmp_path) == ["out.txt"]
    assert isinstance(OutputExistsError("x"), FileExistsError)  # callers catching the built-in still work


def test_a_failed_write_leaves_the_target_and_no_temporary_file(tmp_path):
    p = tmp_path / "keep.json"
    atomic_write_json(p, {"a": 1})

    def bad(_tmp):
        raise InputError("the check refuses it")

    with pytest.raises(InputError):
        atomic_write(p, "{}", overwrite=True, check=bad)
    with pytest.raises(RuntimeError), atomic_file(p, overwrite=True) as f:
        f.write("half")
        raise RuntimeError("killed half-way")
    assert p.read_text() == '{"a": 1}' and _names(tmp_path) == ["keep.json"]


def test_planted_symlinks_do_not_redirect_the_write(tmp_path):
    victim = tmp_path / "victim.txt"
    victim.write_text("precious")
    out = tmp_path / "out"
    out.mkdir()
    # the temporary names the old writers used (".NAME.PID.tmp", ".STEM.partial.EXT"): links planted there
    for name in (f".img0.png.{os.getpid()}.tmp", ".img0.partial.png"):
        (out / name).symlink_to(victim)
    write_image(out / "img0.png", np.zeros((8, 8, 3), np.uint8))
    assert victim.read_text() == "precious"
    # a link at the target itself is replaced (with overwrite), never written through
    link = out / "report.md"
    link.symlink_to(victim)
    with pytest.raises(OutputExistsError):
        atomic_write(link, "new")
    atomic_write(link, "new", overwrite=True)
    assert victim.read_text() == "precious" and not link.is_symlink() and link.read_text() == "new"


def test_a_file_that_appears_while_writing_is_not_clobbered(tmp_path):
    p = tmp_path / "race.txt"
    with pytest.raises(OutputExistsError), atomic_path(p) as tmp:
        tmp.write_text("mine")
        p.write_text("someone else's")  # created by another process meanwhile
    assert p.read_text() == "someone else's" and _names(tmp_path) == ["race.txt"]


def test_permissions_like_a_plain_open_and_kept_when_replacing(tmp_path):
    umask = os.umask(0o022)
    os.umask(umask)
    p = tmp_path / "a.txt"
    atomic_write(p, "x")
    assert stat.S_IMODE(p.stat().st_mode) == 0o666 & ~umask
    p.chmod(0o640)
    atomic_write(p, "y", overwrite=True)
    assert stat.S_IMODE(p.stat().st_mode) == 0o640


def test_check_output_before_any_work(tmp_path):
    (tmp_path / "d").mkdir()
    with pytest.raises(OutputPathError, match="is a folder"):
        check_output(tmp_path / "d")
    with pytest.raises(OutputPathError, match="ending in .png"):
        check_output(tmp_path / "x.jpeg", suffixes=(".png",))
    (tmp_path / "f").write_text("")
    with pytest.raises(OutputPathError, match="is a file, not a folder"):
        check_output(tmp_path / "f" / "sub" / "x.png")
    assert check_output(tmp_path / "new" / "deeper" / "x.png") == tmp_path / "new" / "deeper" / "x.png"
    assert not (tmp_path / "new").exists()  # checking creates nothing


def test_unknown_image_suffix_is_refused_before_writing(tmp_path):
    with pytest.raises(OutputPathError, match="cannot encode"):
        write_image(tmp_path / "noext", np.zeros((8, 8, 3), np.uint8))
    assert _names(tmp_path) == []


def test_figures_are_saved_safely_and_closed(tmp_path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig = plt.figure()
    p = save_figure(fig, tmp_path / "plot.png")
    assert p.read_bytes()[:4] == b"\x89PNG" and not plt.fignum_exists(fig.number)
    with pytest.raises(OutputExistsError):
        save_figure(plt.figure(), p)


@pytest.mark.parametrize(("relative", "message"), [
    ("/etc/passwd", "is an absolute path"),
    ("../outside.png", "leads outside"),
    ("images/../../outside.png", "leads outside"),
    ("", "expected a relative path"),
    (5, "expected a relative path"),
])
def test_paths_from_files_stay_inside_their_root(tmp_path, relative, message):
    with pytest.raises(OutsideRootError, match=message) as info:
        resolve_inside(tmp_path, relative, what="annotations.json: image 3 'file_name'")
    assert str(info.value).startswith("annotations.json: image 3 'file_name'")
    assert isinstance(info.value, ValueError)


def test_symlinks_inside_the_root_may_not_lead_out(tmp_path):
    root, elsewhere = tmp_path / "ds", tmp_path / "elsewhere"
    (root / "images").mkdir(parents=True)
    elsewhere.mkdir()
    (root / "images" / "a.png").write_bytes(b"x")
    (root / "escape").symlink_to(elsewhere)
    assert resolve_inside(root, "images/a.png", what="w") == (root / "images" / "a.png").resolve()
    assert resolve_inside(root, "images/./a.png", what="w").name == "a.png"
    with pytest.raises(OutsideRootError, match="leads outside"):
        resolve_inside(root, "escape/b.png", what="w")


def test_derived_outputs_of_a_resumable_run(tmp_path):
    owner, report = tmp_path / "results.csv", tmp_path / "report.md"
    assert derived_outputs_replaceable(owner, [report]) is False  # nothing there: write new files
    report.write_text("someone's notes")
    with pytest.raises(OutputExistsError, match="not a resumed run"):
        derived_outputs_replaceable(owner, [report])
    assert derived_outputs_replaceable(owner, [report], overwrite=True) is True
    owner.write_text("x,status,error,elapsed_s\n")
    assert derived_outputs_replaceable(owner, [report]) is True  # a resumed run rewrites its own report


# ------------------------------------------------------------- an input is never an output; one writer
def test_a_declared_input_is_never_an_output_overwrite_or_not(tmp_path):
    import contextvars

    from weather_gym.core._io import check_not_input, declare_inputs

    ds = tmp_path / "ds"
    (ds / "images").mkdir(parents=True)
    (ds / "annotations.json").write_text("{}")
    log = tmp_path / "log.npz"
    log.write_bytes(b"x")

    def command():
        declare_inputs(ds, log, None)
        for out in (ds / "annotations.json", ds / "images" / "0.png", ds, log, tmp_path / "x" / ".." / "log.npz"):
            with pytest.raises(OutputPathError, match="never an output"):
                check_output(out, overwrite=True)
        with pytest.raises(OutputPathError, match="never an output"):
            atomic_write(ds / "annotations.json", "scores", overwrite=True)
        with pytest.raises(OutputPathError, match="never an output"):
            check_not_input(ds / "sub", what="--out")
        check_output(tmp_path / "report.json")  # beside the inputs is fine

    contextvars.copy_context().run(command)
    assert (ds / "annotations.json").read_text() == "{}" and log.read_bytes() == b"x"
    check_output(log, overwrite=True)  # the declaration ended with its context (one command)


def test_a_link_to_an_input_is_the_input(tmp_path):
    import contextvars

    from weather_gym.core._io import declare_inputs

    (tmp_path / "model.toml").write_text("")
    (tmp_path / "alias.toml").symlink_to(tmp_path / "model.toml")

    def command():
        declare_inputs(tmp_path / "alias.toml")
        with pytest.raises(OutputPathError):
            check_output(tmp_path / "model.toml", overwrite=True)

    contextvars.copy_context().run(command)


def test_exclusive_refuses_a_second_writer_and_leaves_no_lock_file(tmp_path):
    from weather_gym.core._io import exclusive

    out = tmp_path / "log.npz"
    with exclusive(out):
        with pytest.raises(OutputExistsError, match="another weather-gym run is writing"):
            with exclusive(out):
                pass
        with exclusive(tmp_path / "other.npz"):  # another output in the same folder is another writer's
            pass
    assert _names(tmp_path) == []
    with exclusive(tmp_path):
        with pytest.raises(OutputExistsError, match="busy"), exclusive(tmp_path, message="busy"):
            pass
    with exclusive(out):  # released: the next run gets it
        pass


def test_exclusive_holds_across_processes(tmp_path):
    import subprocess
    import sys

    from weather_gym.core._io import exclusive

    code = ("import sys; from weather_gym.core._io import exclusive\n"
            "try:\n    exclusive(sys.argv[1]).__enter__()\nexcept FileExistsError as e:\n    print(e); sys.exit(3)\n")
    with exclusive(tmp_path / "m.onnx"):
        r = subprocess.run([sys.executable, "-c", code, str(tmp_path / "m.onnx")], capture_output=True, text=True)
    assert r.returncode == 3 and "is writing" in r.stdout


def test_write_failure_types_the_machines_state_and_keeps_bugs():
    import errno

    from weather_gym.core._io import write_failure

    assert isinstance(write_failure("a.mp4", OSError(errno.ENOSPC, "No space left on device")), OutputPathError)
    assert isinstance(write_failure("a.mp4", OSError(errno.EFBIG, "File too large")), OutputPathError)
    bug = OSError(errno.EBADF, "Bad file descriptor")
    assert write_failure("a.mp4", bug) is bug
