"""ASCII layouts and minigrid catalogue validation: every bad input is a SpecError naming file and key."""

from __future__ import annotations

import textwrap
from pathlib import Path

import pytest

from hubsgo_ppl.envs.minigrid.layout import LegendEntry, load_maze_spec, parse_layout
from hubsgo_ppl.resources import envs_dir
from hubsgo_ppl.specs import SpecError

SMALL = textwrap.dedent("""\
    ; a comment line is skipped
    #######
    #A.y.Y#
    #.....#
    #~...G#
    #######
    """)
LEGEND = {"y": LegendEntry(type="key", color="yellow"),
          "Y": LegendEntry(type="door", color="yellow", locked=True)}


def write_task(tmp_path: Path, layout: str = SMALL, options: str | None = None,
               subgoals: str | None = None, name: str = "mini") -> Path:
    """A user task folder: <name>.yaml + <name>.txt."""
    (tmp_path / f"{name}.txt").write_text(layout)
    options = options if options is not None else textwrap.dedent(f"""\
          layout: {name}.txt
          legend:
            y: {{type: key, color: yellow}}
            Y: {{type: door, color: yellow, locked: true}}
          max_steps: 50
        """)
    subgoals = subgoals if subgoals is not None else textwrap.dedent("""\
          - {name: key, kind: carrying, args: {type: key, color: yellow}}
          - {name: door, kind: door_open, args: {color: yellow}}
          - {name: corner, kind: at, args: {cell: [1, 3]}}
          - {name: goal, kind: goal}
        """)
    text = (f"task: {name}\ntitle: Mini\nfamily: minigrid\noptions:\n"
            + textwrap.indent(options, "  ") + "subgoals:\n" + subgoals)
    path = tmp_path / f"{name}.yaml"
    path.write_text(text)
    return path


def test_parse_small_layout():
    lay = parse_layout(SMALL, LEGEND, source="small.txt")
    assert (lay.width, lay.height) == (7, 5)
    assert lay.agent_start == (1, 1) and lay.goal == (5, 3)
    assert lay.lava == frozenset({(1, 3)})
    assert [(o.type, o.color, o.cell, o.locked) for o in lay.objects] == [
        ("key", "yellow", (3, 1), False), ("door", "yellow", (5, 1), True)]
    # border (7*2 + 3*2) + nothing inside
    assert len(lay.walls) == 20 and (0, 0) in lay.walls and (3, 2) not in lay.walls


def test_builtin_layouts_match_the_documented_coordinates():
    kd = load_maze_spec(envs_dir() / "keydoor.yaml").layout
    assert (kd.width, kd.height, kd.agent_start, kd.goal) == (13, 13, (1, 6), (11, 6))
    assert {(o.type, o.color, o.cell) for o in kd.objects} == {
        ("door", "yellow", (8, 4)), ("door", "blue", (8, 8)), ("key", "yellow", (4, 3)),
        ("key", "blue", (4, 9))}
    assert all((8, y) in kd.walls for y in range(13) if y not in (4, 8))
    fr = load_maze_spec(envs_dir() / "fourroom.yaml").layout
    assert (fr.width, fr.height, fr.agent_start, fr.goal) == (13, 13, (1, 1), (11, 11))
    gaps = {(6, 3), (3, 6), (9, 6), (6, 9)}
    wall_line = {(6, y) for y in range(13)} | {(x, 6) for x in range(13)}
    assert wall_line - fr.walls == gaps


@pytest.mark.parametrize("text, fragment", [
    ("#####\n#A.G#\n####\n", "line 3: row has 4 characters"),
    ("#####\n#A.G.\n#####\n", "line 2, column 5: the border must be wall"),
    ("#####\n#AxG#\n#####\n", "line 2, column 3: unknown character 'x'"),
    ("#####\n#AAG#\n#####\n", "found 2 agent starts"),
    ("#####\n#A..#\n#####\n", "found 0 goals"),
    ("; only comments\n", "the layout is empty"),
    ("###\n#A#\n", "at least 3x3"),
])
def test_bad_layouts_name_file_and_line(text, fragment):
    with pytest.raises(SpecError, match="maze.txt") as exc:
        parse_layout(text, {}, source="maze.txt")
    assert fragment in str(exc.value)


@pytest.mark.parametrize("entry, fragment", [
    ({"type": "key"}, "needs a colour"),
    ({"type": "key", "color": "pink"}, "unknown colour 'pink'"),
    ({"type": "door", "color": "red", "locked": True, "open": True}, "both locked and open"),
    ({"type": "key", "color": "red", "locked": True}, "only apply to doors"),
    ({"type": "portal"}, "type"),
])
def test_bad_legend_entries(tmp_path, entry, fragment):
    import yaml
    opts = "layout: mini.txt\nlegend:\n  z: " + yaml.safe_dump(entry, default_flow_style=True)
    path = write_task(tmp_path, layout="#####\n#AzG#\n#####\n", options=opts,
                      subgoals="  - {name: goal, kind: goal}\n")
    with pytest.raises(SpecError) as exc:
        load_maze_spec(path)
    msg = str(exc.value)
    assert str(path) in msg and "options.legend.z" in msg and fragment in msg


@pytest.mark.parametrize("options, key, fragment", [
    ("layout: mini.txt\nmax_step: 10\n", "options.max_step", "unknown key"),
    ("layout: mini.txt\nmax_steps: -3\n", "options.max_steps", "greater than 0"),
    ("layout: mini.txt\nactions: [left, jump]\n", "options.actions", "unknown action(s) ['jump']"),
    ("layout: mini.txt\nactions: [left, left]\n", "options.actions", "without repeats"),
    ("layout: mini.txt\nstart_dir: north\n", "options.start_dir", "right"),
    ("layout: mini.txt\nobs_mode: pixels\n", "options.obs_mode", "symbolic"),
    ("layout: mini.txt\nlegend: {'#': {type: wall}}\n", "options.legend", "built in"),
    ("max_steps: 10\n", "options.layout", "required key is missing"),
    ("layout: nowhere.txt\n", "options.layout", "not found"),
])
def test_bad_options_name_file_and_key(tmp_path, options, key, fragment):
    path = write_task(tmp_path, layout="#####\n#A.G#\n#####\n", options=options,
                      subgoals="  - {name: goal, kind: goal}\n")
    with pytest.raises(SpecError) as exc:
        load_maze_spec(path)
    msg = str(exc.value)
    assert str(path) in msg and key in msg and fragment in msg, msg


@pytest.mark.parametrize("subgoal, key, fragment", [
    ("{name: s, kind: teleport}", "subgoals[0] (s).kind", "unknown predicate kind 'teleport'"),
    ("{name: s, kind: at, args: {cell: [9, 1]}}", "subgoals[0] (s).args.cell", "outside the 7x5 grid"),
    ("{name: s, kind: at, args: {cell: [0, 2]}}", "subgoals[0] (s).args.cell", "is a wall in mini.txt"),
    ("{name: s, kind: at, args: {where: [1, 1]}}", "subgoals[0] (s).args", "unknown key"),
    ("{name: s, kind: carrying, args: {type: key, color: blue}}", "subgoals[0] (s).args",
     "no blue key in mini.txt (it has: yellow key)"),
    ("{name: s, kind: carrying, args: {type: ball, color: yellow}}", "subgoals[0] (s).args",
     "no yellow ball"),
    ("{name: s, kind: door_open, args: {color: red}}", "subgoals[0] (s).args.color",
     "no red door in mini.txt (door colours: yellow)"),
    ("{name: s, kind: door_open, args: {cell: [2, 2]}}", "subgoals[0] (s).args.cell", "no door at [2, 2]"),
    ("{name: s, kind: door_open, args: {}}", "subgoals[0] (s).args", "exactly one of color or cell"),
    ("{name: s, kind: goal, args: {cell: [1, 1]}}", "subgoals[0] (s).args.cell", "unknown key"),
])
def test_bad_subgoals_name_file_and_key(tmp_path, subgoal, key, fragment):
    path = write_task(tmp_path, subgoals=f"  - {subgoal}\n")
    with pytest.raises(SpecError) as exc:
        load_maze_spec(path)
    msg = str(exc.value)
    assert str(path) in msg and key in msg and fragment in msg, msg


def test_ambiguous_door_colour_asks_for_a_cell(tmp_path):
    layout = "#######\n#AY.YG#\n#######\n"
    path = write_task(tmp_path, layout=layout, subgoals="  - {name: d, kind: door_open, args: {color: yellow}}\n")
    with pytest.raises(SpecError, match=r"2 yellow doors in mini.txt; name the door by cell"):
        load_maze_spec(path)
    ok = write_task(tmp_path, layout=layout, subgoals="  - {name: d, kind: door_open, args: {cell: [4, 1]}}\n")
    pred = load_maze_spec(ok).predicates[0]
    assert (pred.kind, pred.target, pred.index) == ("door_open", (4, 1), 1)


def test_valid_user_task_compiles_predicates(tmp_path):
    spec = load_maze_spec(write_task(tmp_path))
    assert spec.subgoal_names == ["key", "door", "corner", "goal"]
    assert [(p.kind, p.target, p.index) for p in spec.predicates] == [
        ("carrying", (3, 1), 0), ("door_open", (5, 1), 0), ("at", (1, 3), -1), ("goal", (5, 3), -1)]
    assert spec.max_steps == 50 and spec.carry_kinds == (("key", "yellow"),)


def test_spec_cache_sees_edited_layout(tmp_path):
    path = write_task(tmp_path, layout="#####\n#A.G#\n#####\n", subgoals="  - {name: goal, kind: goal}\n")
    assert load_maze_spec(path).layout.goal == (3, 1)
    import os
    txt = tmp_path / "mini.txt"
    txt.write_text("#####\n#AG.#\n#####\n")
    st = txt.stat()
    os.utime(txt, ns=(st.st_atime_ns, st.st_mtime_ns + 10_000_000))
    assert load_maze_spec(path).layout.goal == (2, 1)


@pytest.mark.parametrize("how", ["up the tree", "absolute", "symbolic link"])
def test_a_layout_is_read_only_from_the_catalogues_folder(tmp_path, capsys, how):
    outside = tmp_path / "elsewhere" / "other.txt"
    outside.parent.mkdir()
    outside.write_text("#####\n#A.G#\n#####\n")          # a valid layout: only where it lies is wrong
    folder = tmp_path / "task"
    folder.mkdir()
    if how == "symbolic link":
        (folder / "link.txt").symlink_to(outside)
    named = {"up the tree": "../elsewhere/other.txt", "absolute": str(outside), "symbolic link": "link.txt"}[how]
    path = write_task(folder, options=f"layout: {named}\n", subgoals="  - {name: goal, kind: goal}\n")
    with pytest.raises(SpecError) as exc:
        load_maze_spec(path)
    msg = str(exc.value)
    assert "\n" not in msg and msg.startswith(f"{path}: options.layout: {named!r} ") and "catalogue's folder" in msg
    # the command line refuses it in that one line, exit 2
    from hubsgo_ppl.cli import main

    assert main(["tasks", str(path)]) == 2
    assert capsys.readouterr().err.strip().splitlines() == [f"hubsgo: error: {msg}"]


def test_a_layout_in_a_folder_below_the_catalogue_is_read(tmp_path):
    (tmp_path / "layouts").mkdir()
    (tmp_path / "layouts" / "small.txt").write_text("#####\n#A.G#\n#####\n")
    path = write_task(tmp_path, options="layout: layouts/./small.txt\n", subgoals="  - {name: goal, kind: goal}\n")
    assert load_maze_spec(path).layout.goal == (3, 1)


@pytest.mark.parametrize("first", ["", "; a comment line first\n"])
def test_a_layout_saved_with_a_byte_order_mark_reads_as_without(tmp_path, first):
    path = write_task(tmp_path, layout="#####\n#A.G#\n#####\n", subgoals="  - {name: goal, kind: goal}\n")
    (tmp_path / "mini.txt").write_bytes(("\ufeff" + first + "#####\n#A.G#\n#####\n").encode("utf-8"))
    spec = load_maze_spec(path)
    assert (spec.layout.width, spec.layout.height) == (5, 3)


def test_two_starts_or_goals_are_named_by_line_and_column_and_a_legend_goal_by_its_character():
    with pytest.raises(SpecError, match=r"found 2 agent starts 'A' at line 3, column 2 \('A', cell \[1, 1\]\) and "
                                        r"line 4, column 4 \('A', cell \[3, 2\]\)"):
        parse_layout("; comment\n#####\n#A..#\n#..A#\n#..G#\n#####\n", {})
    with pytest.raises(SpecError, match=r"found 2 goals at line 2, column 4 \('g', cell \[3, 1\]\) and line 4, "
                                        r"column 4 \('G', cell \[3, 3\]\)"):
        parse_layout("#####\n#A.g#\n#...#\n#..G#\n#####\n", {"g": LegendEntry(type="goal")})
