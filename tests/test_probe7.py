"""Bad input found by the seventh hostile probe, kept as tests (each broke the one-line-error rule)."""

from __future__ import annotations

import warnings

import pytest

from scenes import InvalidMeshError, load_scene
from tests.test_probe6 import GOOD_FACES, _ply_text


@pytest.mark.parametrize(
    "edit, message",
    [
        # numpy's "setting an array element with a sequence" named no record
        (lambda t: t.replace("\n4 0 0\n", "\n4 0\n"), r"element 'vertex' record 1 \(line 13\) holds 2 values"),
        (lambda t: t.replace("4 1 5 6 2 2 0", "4 1 5 6 2 2"), r"element 'face' record 3 \(line 23\) holds 6 values"),
        (lambda t: t.replace("4 1 5 6 2 2 0", "4 1 5 six 2 2 0"), r"element 'face' record 3 \(line 23\) holds a value"),
        (lambda t: t.rsplit("\n", 3)[0] + "\n", r"element 'face' declares 6 records, the body ends at record 4"),
    ],
)
def test_an_ascii_ply_record_that_does_not_fit_its_header_is_named_with_its_line(edit, message, tmp_path):
    path = tmp_path / "bad.ply"
    text = _ply_text(GOOD_FACES)
    path.write_text(text)
    assert len(load_scene(str(path)).mesh.faces) == 12
    path.write_text(edit(text))
    with pytest.raises(InvalidMeshError, match=message):
        load_scene(str(path))


def test_an_index_outside_the_vertices_is_numbered_as_the_format_numbers_vertices(tmp_path):
    """PLY counts vertices from 0: its index -5 was reported as "vertex -4 ... outside 1..8"."""
    path = tmp_path / "bad.ply"
    path.write_text(_ply_text(["4 0 1 2 -5 0 0", *GOOD_FACES[1:]]))
    with pytest.raises(InvalidMeshError, match=r"refer to vertex -5 or other vertices outside 0\.\.7"):
        load_scene(str(path))
    obj = tmp_path / "bad.obj"
    obj.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\no floor\nf 1 2 9\n")
    with pytest.raises(InvalidMeshError, match=r"refer to vertex 9 or other vertices outside 1\.\.3"):
        load_scene(str(obj))


@pytest.mark.parametrize(
    "edit, message",
    [
        # trimesh skipped a line it did not know: the body was read from the wrong place
        (lambda t: "ply\n" + t, r"PLY header line 2: 'ply' is no header line"),
        (lambda t: t.replace("property float y\n", "float y\n"), r"header line 5: 'float y' is no header line"),
        (lambda t: t.replace("list uchar int vertex", "list uchar 0 vertex"), r"header line 8: bad property"),
        (lambda t: t.replace("int vertex_indices", "int corners"), r"the PLY face element has no vertex_indices list"),
        (lambda t: t.replace("property float y\n", ""), r"the PLY vertex element has no y number property"),
        (
            lambda t: t.replace("format ascii 1.0\nelement vertex 8\n", "element vertex 8\nformat ascii 1.0\n"),
            r"PLY header line 2: an element before the 'format' line",
        ),
        (lambda t: t.replace("element face 6", "element vertex 6"), r"line 7: a second element 'vertex'"),
        # more face rows than declared: the rest was dropped without a word
        (
            lambda t: t.replace("element face 6", "element face 5"),
            r"declares 8 vertex and 5 face records, 13 lines, but",
        ),
    ],
)
def test_ply_headers_that_trimesh_would_misread_are_refused(edit, message, tmp_path):
    path = tmp_path / "bad.ply"
    path.write_text(edit(_ply_text(GOOD_FACES)))
    with pytest.raises(InvalidMeshError, match=message):
        load_scene(str(path))
    path.write_text(_ply_text(GOOD_FACES) + "\n\n  \n")  # trailing blank lines are no records
    assert len(load_scene(str(path)).mesh.faces) == 12


def test_a_closed_stdout_or_stderr_drops_what_is_written_and_the_report_is_kept(tmp_path):
    """With descriptor 1 closed Python's sys.stdout is None: every write ended in an AttributeError
    traceback after the report was written, and the report's file could take descriptor 1. A command
    whose product is what it prints (probe 40: ``scenes list``, ``scenes info``, ``--version`` exited
    0 having written nothing) fails instead, as ``ls >&-`` does."""
    import json
    import subprocess
    import sys
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    nbs = f"{sys.executable} -c 'import sys; from train.cli import main; sys.argv[0] = \"nbs\"; sys.exit(main())'"
    out = tmp_path / "o"
    for command, code in (
        (f"{nbs} scenes info l_room >&-", 1),
        (f"{nbs} scenes list >&-", 1),
        (f"{nbs} --version >&-", 1),
        (f"{nbs} scenes info l_room 2>&-", 0),
        (f"{nbs} scenes info nope.json >&-", 1),
        (f"{nbs} scenes info nope.json 2>&-", 1),
        (f"{nbs} scan --scene l_room --preset fast --max-scans 1 --no-steps --out {out} >&- 2>&-", 0),
    ):
        proc = subprocess.run(["bash", "-c", command], cwd=root, capture_output=True, text=True, timeout=300)
        assert proc.returncode == code, (command, proc.stderr)
        assert "Traceback" not in proc.stderr, proc.stderr
        if "nope" not in command and code == 1:
            assert proc.stderr.startswith("nbs: error: stdout is closed"), proc.stderr
    assert json.loads((out / "metrics.json").read_text())["scans"] == 1


# ---------------------------------------------------------------------- IFC reference cycles and chains
def _ifc(tmp_path, edit):
    from pathlib import Path

    text = (Path(__file__).parent / "data" / "two_rooms.ifc").read_text()
    head, tail = text.rsplit("ENDSEC;", 1)
    path = tmp_path / "edited.ifc"
    path.write_text(edit(head) + "ENDSEC;" + tail)
    return path


def _placement_chain(head: str) -> str:
    chain = [f"#{1000 + i}=IFCLOCALPLACEMENT(#{999 + i if i else 25},#58);\n" for i in range(300)]
    return head.replace("#59=IFCLOCALPLACEMENT(#25,#58);", "#59=IFCLOCALPLACEMENT(#1299,#58);") + "".join(chain)


def _aggregation_chain(head: str) -> str:
    proxies = [f"#{2000 + i}=IFCBUILDINGELEMENTPROXY('p{i}',$,'p',$,$,$,$,$,$);\n" for i in range(100)]
    rels = [f"#{3000 + i}=IFCRELAGGREGATES('r{i}',$,$,$,#{2000 + i},(#{2001 + i}));\n" for i in range(99)]
    return head + "".join(proxies + rels) + "#3200=IFCRELAGGREGATES('x',$,$,$,#2099,(#37));\n"


@pytest.mark.parametrize(
    "edit, message",
    [
        # ifcopenshell's geometry engine looped on it, deaf to SIGTERM
        (
            lambda h: (
                h.replace("'SweptSolid',(#46));", "'SweptSolid',(#900));", 1)
                + "#900=IFCBOOLEANRESULT(.DIFFERENCE.,#900,#46);\n"
            ),
            r"the file's references form a cycle: #900 \(IFCBOOLEANRESULT\) -> #900 \(IFCBOOLEANRESULT\)",
        ),
        # a RecursionError traceback from ifcopenshell's placement
        (_placement_chain, r"starts a chain of 30\d references, at most 160 \(real files hold 14 at most\)"),
        # a part of itself: the loader looped forever; a long chain took it through every element
        (
            lambda h: h + "#901=IFCRELAGGREGATES('x',$,$,$,#37,(#37));\n",
            r"the file's decompositions form a cycle: #37 \(IfcWall\) -> #37 \(IfcWall\)",
        ),
        (_aggregation_chain, r"#2000 \(IfcBuildingElementProxy\) starts a chain of 100 decompositions, at most 64"),
        (lambda h: h + "#37=IFCWALL('x',$,'again',$,$,#59,#48,$,$);\n", r"instance #37 is defined twice"),
    ],
)
def test_ifc_references_that_cycle_or_chain_too_deep_are_refused_before_a_reader_follows_them(edit, message, tmp_path):
    pytest.importorskip("ifcopenshell")
    from scenes import IfcError

    with pytest.raises(IfcError, match=message):
        load_scene(str(_ifc(tmp_path, edit)), storey=0)


def test_references_inside_strings_and_comments_are_no_references(tmp_path):
    pytest.importorskip("ifcopenshell")
    # A name holding '#37', a ';' and a quote, and a comment naming #37: none is an edge or a statement.
    path = _ifc(
        tmp_path,
        lambda h: h.replace("'wall south'", "'wall ''#37''; #37=IFCWALL('").replace(
            "#47=IFCSHAPE", "/* #47 refers to #47; */ #47=IFCSHAPE"
        ),
    )
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no reference dangles: the comment hid no statement
        assert len(load_scene(str(path), storey=0).mesh.faces) > 0


def test_a_command_with_nothing_to_keep_stops_at_a_signal_not_at_its_end():
    """`nbs scenes info` recorded a SIGTERM and went on to its end: a load of minutes was deaf to it."""
    import signal
    import subprocess
    import sys
    import time
    from pathlib import Path

    code = (
        "import sys, train.cli as c\n"
        "def forever(args):\n"
        "    print('working', file=sys.stderr, flush=True)\n"
        "    while True:\n"
        "        pass\n"
        "c.run = forever\n"
        "sys.exit(c.main(['scenes', 'info', 'l_room']))\n"
    )
    root = Path(__file__).resolve().parents[1]
    proc = subprocess.Popen([sys.executable, "-c", code], cwd=root, stderr=subprocess.PIPE, text=True)
    assert proc.stderr.readline().strip() == "working"
    sent = time.monotonic()
    proc.send_signal(signal.SIGTERM)
    err = proc.communicate(timeout=60)[1]
    assert proc.returncode == 128 + signal.SIGTERM and time.monotonic() - sent < 10
    assert err.strip() == "nbs: stopped by SIGTERM" and "Traceback" not in err


def test_a_signal_recorded_while_libraries_loaded_stops_the_command_when_it_starts():
    import subprocess
    import sys
    from pathlib import Path

    code = (
        "import os, signal, time\n"
        "from train.stopping import defer_signals, interrupt_on_signals, pending_signal\n"
        "defer_signals()\n"
        "os.kill(os.getpid(), signal.SIGTERM)\n"
        "time.sleep(0.2)\n"
        "assert pending_signal() == signal.SIGTERM\n"
        "try:\n"
        "    interrupt_on_signals()\n"
        "except KeyboardInterrupt:\n"
        "    print('stopped')\n"
    )
    root = Path(__file__).resolve().parents[1]
    proc = subprocess.run([sys.executable, "-c", code], cwd=root, capture_output=True, text=True, timeout=60)
    assert proc.stdout.strip() == "stopped", proc.stderr


@pytest.mark.parametrize(
    ("patched", "argv", "line"),
    [
        ("run_scan", ["scan", "--scene", "l_room", "--out", "OUT"], "nbs scan: interrupted"),
        ("run", ["scenes", "info", "l_room"], "nbs: stopped by SIGINT"),
    ],
)
def test_an_interrupt_a_c_extension_turns_into_its_own_error_is_an_interrupt(patched, argv, line, tmp_path):
    """A second Ctrl-C inside `import open3d` came out as `ImportError: initialization failed` and a
    70-line traceback blaming the install."""
    import subprocess
    import sys
    from pathlib import Path

    code = (
        "import sys, train.cli as c\n"
        "def boom(args):\n"
        "    try:\n"
        "        raise KeyboardInterrupt\n"
        "    except KeyboardInterrupt as exc:\n"
        "        raise ImportError('initialization failed') from exc\n"
        f"c.{patched} = boom\n"
        f"sys.exit(c.main({[str(tmp_path / 'o') if a == 'OUT' else a for a in argv]!r}))\n"
    )
    root = Path(__file__).resolve().parents[1]
    proc = subprocess.run([sys.executable, "-c", code], cwd=root, capture_output=True, text=True, timeout=120)
    assert (proc.returncode, proc.stderr.strip()) == (130, line)


def test_an_error_of_its_own_is_not_taken_for_an_interrupt():
    from train.cli import interrupted

    try:
        try:
            raise ValueError("x")
        except ValueError as exc:
            raise ImportError("y") from exc
    except ImportError as exc:
        assert not interrupted(exc)
    assert interrupted(KeyboardInterrupt())


# ---------------------------------------------------------------------- binary PLY with lists of several lengths
def _binary_ply(faces: list[str], endian: str = "<") -> bytes:
    import struct

    vertices = [(0, 0, 0), (4, 0, 0), (4, 3, 0), (0, 3, 0), (0, 0, 2.5), (4, 0, 2.5), (4, 3, 2.5), (0, 3, 2.5)]
    name = "binary_little_endian" if endian == "<" else "binary_big_endian"
    header = (
        f"ply\nformat {name} 1.0\nelement vertex 8\nproperty float x\nproperty float y\nproperty float z\n"
        f"element face {len(faces)}\nproperty list uchar int vertex_indices\nproperty uchar label\n"
        "property int room\nend_header\n"
    ).encode()
    body = b"".join(struct.pack(endian + "3f", *v) for v in vertices)
    for row in faces:
        n, *rest = (int(x) for x in row.split())
        body += struct.pack(f"{endian}B{n}iBi", n, *rest)
    return header + body


@pytest.mark.parametrize("endian", ["<", ">"])
def test_a_binary_ply_mixing_triangles_and_quads_loads_as_its_ascii_twin(endian, tmp_path):
    """trimesh reads binary lists of one length only: the mix most exporters write was refused."""
    mixed = ["3 0 1 2 0 0", "3 0 2 3 0 0", *GOOD_FACES[1:]]  # a floor of two triangles, walls of quads
    (tmp_path / "a.ply").write_text(_ply_text(mixed))
    (tmp_path / "b.ply").write_bytes(_binary_ply(mixed, endian))
    a, b = load_scene(str(tmp_path / "a.ply")), load_scene(str(tmp_path / "b.ply"))
    assert len(b.mesh.faces) == len(a.mesh.faces) == 12
    assert (b.mesh.faces == a.mesh.faces).all() and (b.face_labels == a.face_labels).all()
    assert abs(b.mesh.vertices - a.mesh.vertices).max() < 1e-6


@pytest.mark.parametrize(
    "damage, message",
    [
        (lambda d: d[:-3], r"PLY face 6's 'room' runs past the end of the file \(1 bytes are left\)"),
        (lambda d: d + b"\0\0", r"2 bytes follow the last record the PLY header declares"),
        (
            lambda d: d.replace(b"\x04\x00\x00\x00\x00", b"\xff\x00\x00\x00\x00", 1),
            r"PLY face \d's 'vertex_indices' runs past",
        ),
    ],
)
def test_a_damaged_binary_ply_with_lists_of_several_lengths_is_named(damage, message, tmp_path):
    mixed = ["3 0 1 2 0 0", "3 0 2 3 0 0", *GOOD_FACES[1:]]
    path = tmp_path / "b.ply"
    path.write_bytes(damage(_binary_ply(mixed)))
    with pytest.raises(InvalidMeshError, match=message):
        load_scene(str(path))


@pytest.mark.parametrize(("seed", "kind"), [(-1, ValueError), (1.5, TypeError), ("1", TypeError), (True, TypeError)])
def test_a_generator_seed_that_is_no_integer_is_named(seed, kind):
    """numpy's "expected non-negative integer" named neither the seed nor the generator."""
    from scenes import generate_plan

    with pytest.raises(kind, match=r"the generator's seed must be an integer >= 0"):
        generate_plan(seed)


def test_two_outputs_naming_one_file_are_refused_before_the_work(tmp_path, capsys):
    """`--out x.png --show x.png` wrote the plan, then its picture over it, and said both were written."""
    from train.cli import EXIT_USAGE, main

    (tmp_path / "d").mkdir()
    for show in ("x.png", "d/../x.png"):
        with pytest.raises(SystemExit) as stopped:
            main(
                ["scenes", "generate", "--seed", "1", "--out", str(tmp_path / "x.png"), "--show", str(tmp_path / show)]
            )
        code = stopped.value.code
        err = capsys.readouterr().err
        # Now refused sooner: a plan is JSON, so it never shares a picture's name.
        assert code == EXIT_USAGE and "a floor plan is JSON" in err, err
    assert not (tmp_path / "x.png").exists()
    link = tmp_path / "link.rrd"
    link.symlink_to(tmp_path / "run")
    code = main(["scan", "--scene", "l_room", "--out", str(tmp_path / "run"), "--record", str(link)])
    assert code == EXIT_USAGE and "--out and --record both name" in capsys.readouterr().err


@pytest.mark.parametrize(
    "old, new, message",
    [
        # read as lying in the plan: the wall extruded sideways, without a word
        (
            "#40=IFCDIRECTION((0.,0.,1.));",
            "#40=IFCDIRECTION((0.,1.));",
            r"the extrusion #46 runs along #40, a direction of 2",
        ),
        ("#40=IFCDIRECTION((0.,0.,1.));", "#40=IFCDIRECTION((0.,0.,1.,0.));", r"the direction #40 has 4 components"),
        # sorted after every other storey: --storey 0 became the upper one
        (
            "'EG',$,$,#25,$,$,$,0.);",
            "'EG',$,$,$,$,$,$,1.E300);",
            r"the storey #14 'EG' lies at 1e\+300 m; storeys lie within 10,000 m of the origin",
        ),
    ],
)
def test_ifc_directions_and_elevations_no_building_has_are_refused(old, new, message, tmp_path):
    pytest.importorskip("ifcopenshell")
    from scenes import IfcError

    with pytest.raises(IfcError, match=message):
        load_scene(str(_ifc(tmp_path, lambda h: h.replace(old, new))), storey=0)


@pytest.mark.parametrize("scale", ["0.", "-1."])
def test_a_mapped_item_scaled_by_zero_or_less_is_refused(scale, tmp_path):
    pytest.importorskip("ifcopenshell")
    from scenes import IfcError
    from tests.test_probe5 import _fzk

    old = "#19184= IFCCARTESIANTRANSFORMATIONOPERATOR3D($,$,#19182,$,$);"
    path = _fzk(tmp_path, old, old.replace(",$,$);", f",{scale},$);"))
    with pytest.raises(
        IfcError, match=rf"the transformation #19184 scales by {scale.rstrip('.')}; a scale is a number > 0"
    ):
        load_scene(str(path), storey=0)


def test_a_reference_that_is_no_instance_name_is_refused_and_dangling_ones_are_said(tmp_path):
    """`#-115` was read without a word; a file cut in half and given back its end marker lost its
    ceilings silently (its relations name instances it no longer holds)."""
    pytest.importorskip("ifcopenshell")
    from scenes import IfcError
    from scenes.stepgraph import DanglingReferencesWarning

    with pytest.raises(IfcError, match=r"'#-25' names no instance"):
        load_scene(
            str(_ifc(tmp_path, lambda h: h.replace("#59=IFCLOCALPLACEMENT(#25,", "#59=IFCLOCALPLACEMENT(#-25,")))
        )
    cut = _ifc(tmp_path, lambda h: h + "#990=IFCRELAGGREGATES('x',$,$,$,#14,(#991,#992));\n")
    with pytest.warns(
        DanglingReferencesWarning, match=r"2 reference\(s\) name instances the file does not define \(#990 -> #991"
    ):
        load_scene(str(cut), storey=0)


def test_a_folder_or_a_file_without_a_suffix_given_as_a_scene_is_said_to_be_one(tmp_path, monkeypatch):
    from scenes import UnknownSceneError

    monkeypatch.chdir(tmp_path)
    (tmp_path / "plans").mkdir()
    (tmp_path / "storey").write_text("{}")
    with pytest.raises(UnknownSceneError, match=r"plans: a folder, not a scene file"):
        load_scene("plans")
    with pytest.raises(UnknownSceneError, match=r"storey: a file without a type suffix \(\.json"):
        load_scene("storey")


def test_generator_doors_taller_than_the_ceiling_allows_and_endless_episodes_are_refused():
    from scenes.generator import GeneratorConfig
    from train.ppo import TrainConfig

    with pytest.raises(ValueError, match=r"door_height \[29, 30\] must stay 0\.3 m below the lowest ceiling"):
        GeneratorConfig(door_height=(29, 30))
    with pytest.raises(ValueError, match=r"max_episode_steps must be at most 100,000"):
        TrainConfig(max_episode_steps=10**12)


# ---------------------------------------------------------------------- probe 8
def test_a_reference_written_with_a_blank_after_its_hash_is_a_reference(tmp_path):
    """ifcopenshell reads `# 900` and `#\\n900` as #900: the reference check read neither, and a cycle
    written so hung or crashed the geometry engine again."""
    pytest.importorskip("ifcopenshell")
    from scenes import IfcError

    for written in ("# 900", "#\n900"):
        path = _ifc(
            tmp_path,
            lambda h, w=written: (
                h.replace("'SweptSolid',(#46));", "'SweptSolid',(#900));", 1)
                + f"#900=IFCBOOLEANRESULT(.DIFFERENCE.,{w},#46);\n"
            ),
        )
        with pytest.raises(IfcError, match=r"references form a cycle: #900 \(IFCBOOLEANRESULT\) -> #900"):
            load_scene(str(path), storey=0)


@pytest.mark.parametrize(
    "edit, message",
    [
        # trimesh kept one of the two columns (ASCII: silently the wrong one; binary: a numpy traceback)
        (
            lambda t: t.replace("property float z\n", "property float z\nproperty int x\n"),
            r"line 7: the vertex element's property 'x' again",
        ),
        (
            lambda t: t.replace("format ascii 1.0\n", "format ascii 1.0\ncomment see end_header below\n"),
            r"line 3 holds 'end_header' within it",
        ),
        (lambda t: t.replace("\n4 0 1 2 3 0 0\n", "\n\n4 0 1 2 3 0 0\n"), r"line 20 of the PLY body is blank"),
    ],
)
def test_ply_headers_and_bodies_readers_misread_are_named(edit, message, tmp_path):
    path = tmp_path / "bad.ply"
    path.write_text(edit(_ply_text(GOOD_FACES)))
    with pytest.raises(InvalidMeshError, match=message):
        load_scene(str(path))


def test_a_ply_header_of_many_comments_loads(tmp_path):
    """A valid PLY with a 77 kB header was "not a PLY file"."""
    path = tmp_path / "long.ply"
    text = _ply_text(GOOD_FACES)
    comments = ("comment " + "y" * 70 + "\n") * 1000
    path.write_text(text.replace("format ascii 1.0\n", "format ascii 1.0\n" + comments))
    assert len(load_scene(str(path)).mesh.faces) == 12


def test_a_report_that_would_write_over_its_own_scene_is_refused(tmp_path, capsys):
    """`nbs scan --scene D/cloud.ply --out D --force` wrote the report's cloud.ply over the scene."""
    from scenes.importers import export_scene
    from train.cli import EXIT_USAGE, main

    scene = tmp_path / "cloud.ply"
    export_scene(load_scene("l_room"), scene)
    before = scene.read_bytes()
    code = main(["scan", "--scene", str(scene), "--out", str(tmp_path), "--force", "--max-scans", "1"])
    err = capsys.readouterr().err
    assert code == EXIT_USAGE and f"--out writes cloud.ply in {tmp_path}, which is --scene" in err, err
    assert scene.read_bytes() == before


def test_running_out_of_memory_is_one_line(monkeypatch, capsys):
    """`--voxel 0.01` under a memory limit ended in a 63-line MemoryError traceback."""
    import numpy as np

    import train.cli as cli

    def greedy_for_memory(args):
        np.zeros(1 << 62, dtype=np.uint8)  # numpy refuses before asking the system

    monkeypatch.setattr(cli, "run_scan", greedy_for_memory)
    assert cli.main(["scan", "--scene", "l_room"]) == cli.EXIT_SCENE_ERROR
    err = capsys.readouterr().err.strip()
    assert err.startswith("nbs: error: out of memory (Unable to allocate") and "--voxel" in err
    assert len(err.splitlines()) == 1


def test_a_truncated_ifc_that_opens_with_a_comment_is_still_found_truncated(tmp_path):
    pytest.importorskip("ifcopenshell")
    from pathlib import Path

    from scenes import IfcError

    text = (Path(__file__).parent / "data" / "two_rooms.ifc").read_text()
    path = tmp_path / "cut.ifc"
    path.write_text("/* exported by hand */\n" + text)
    assert len(load_scene(str(path), storey=0).mesh.faces) > 0
    path.write_text("/* exported by hand */\n" + text[: len(text) // 2])
    with pytest.raises(IfcError, match=r"truncated, the file does not end with END-ISO-10303-21;"):
        load_scene(str(path), storey=0)


# ---------------------------------------------------------------------- probe 9: glTF references, fans, instances
@pytest.mark.parametrize(
    "edit, message",
    [
        # a part vanished without a word (and -1 was the last mesh or accessor)
        (lambda d: d["nodes"][0].update(mesh=99), r"nodes\[0\]\.mesh is 99, but the file has \d+ mesh"),
        (lambda d: d["nodes"][0].update(mesh=-1), r"nodes\[0\]\.mesh must be an integer >= 0, got -1"),
        (
            lambda d: d["meshes"][0]["primitives"][0]["attributes"].update(POSITION=-1),
            r"meshes\[0\]\.primitives\[0\]\.attributes\.POSITION is -1, but the file has \d+ accessor",
        ),
        (lambda d: d["meshes"][0]["primitives"][0].update(indices=99), r"primitives\[0\]\.indices is 99"),
        (lambda d: d["meshes"][0]["primitives"][0].update(attributes={}), r"attributes has no POSITION"),
        # trimesh drops a triangle fan whole
        (lambda d: d["meshes"][0]["primitives"][0].update(mode=6), r"is a triangle fan \(mode 6\)"),
    ],
)
def test_gltf_references_fans_and_instances_are_checked_before_the_reader(edit, message, tmp_path):
    from tests.test_scene_probe2 import gltf_doc, room_parts, write_gltf

    doc = gltf_doc(room_parts())
    assert len(load_scene(str(write_gltf(tmp_path / "ok.gltf", doc))).mesh.faces) > 0
    edit(doc)
    with pytest.raises(InvalidMeshError, match=message):
        load_scene(str(write_gltf(tmp_path / "x.gltf", doc)))


def test_the_faces_a_gltf_s_instances_draw_are_counted_before_the_reader_builds_them(tmp_path, monkeypatch):
    """100,000 nodes of one small mesh (a 7.7 MB file) were built into 31 million faces before the
    face bound was met, and the memory ran out first. Here the bound is lowered to the room's faces."""
    import scenes.limits as limits
    from scenes import StoreySizeError
    from tests.test_scene_probe2 import gltf_doc, room_parts, write_gltf

    doc = gltf_doc(room_parts())
    room = len(load_scene(str(write_gltf(tmp_path / "ok.gltf", doc))).mesh.faces)
    monkeypatch.setattr(limits, "MAX_FACES", room + 10)
    assert len(load_scene(str(write_gltf(tmp_path / "ok.gltf", doc))).mesh.faces) == room
    doc["nodes"].extend({"name": f"clutter_{i}", "mesh": 0} for i in range(10))
    doc["scenes"][0]["nodes"].extend(range(len(doc["nodes"]) - 10, len(doc["nodes"])))
    import scenes.importers as importers

    def never(*args, **kwargs):
        raise AssertionError("the reader built the instances")

    monkeypatch.setattr(importers.trimesh, "load", never)
    with pytest.raises(
        StoreySizeError, match=rf"the mesh has [\d,]+ faces \(the most nbs-env loads is {room + 10:,}\)"
    ):
        load_scene(str(write_gltf(tmp_path / "x.gltf", doc)))


def test_a_training_seed_numpy_cannot_take_is_refused_by_name():
    """`nbs train --seed 4294967296` ended in a traceback from stable-baselines3's set_random_seed."""
    from nbs_env.errors import ConfigError
    from train.ppo import TrainConfig

    assert TrainConfig(seed=2**32 - 1).seed == 2**32 - 1
    with pytest.raises(ConfigError, match=r"seed must be below 2\*\*32 = 4,294,967,296, got 4,294,967,296"):
        TrainConfig(seed=2**32)
