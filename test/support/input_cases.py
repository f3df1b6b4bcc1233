"""Concrete bad inputs, one or more per class of the input contract (docs/guide/scenes.md).

Each case: (class number, test id, scene file bytes or None for a path argument, extra
command-line arguments, the start of the expected error after "polymatch: error: ").
"""

BASE = b"""name: t
dimension: 2
seed: 1
model: {order: 1}
time: {t_end: 2.0}
integrator: {method: rkmk4, dt: 0.05}
groups:
  - {name: g, shape: triangle, count: 3}
"""


def scene(*lines, groups=None):
    """BASE with top-level ``key: value`` lines replaced or added, and optionally other groups."""
    text = BASE.decode()
    head, tail = text.split("groups:\n")
    for line in lines:
        key = line.split(":", 1)[0]
        head = "".join(x + "\n" for x in head.splitlines() if not x.startswith(key + ":"))
        head += line + "\n"
    return (head + "groups:\n" + (tail if groups is None else groups + "\n")).encode()


def bomb(levels=9, fan=9):
    lines = ["a0: &a0 [lol]"]
    for i in range(1, levels + 1):
        lines.append(f"a{i}: &a{i} [" + ", ".join([f"*a{i - 1}"] * fan) + "]")
    return ("description:\n  " + "\n  ".join(lines)).encode()


def nested(depth):
    return b"name: t\nx: " + b"[" * depth + b"]" * depth + b"\n"


CASES = [
    # 1. encodings
    (1, "binary_file", bytes(range(256)) * 4, [], "SCENE: not UTF-8 text"),
    (1, "latin1_file", BASE.replace(b"name: t", b"name: caf\xe9"), [], "SCENE: not UTF-8 text"),
    (1, "utf16_file", BASE.decode().encode("utf-16"), [], "SCENE: is UTF-16 text"),
    # 2. nesting
    (2, "nested_100000_deep", nested(100_000), [], "x[0][0]"),
    (2, "nested_mapping_deep", b"a: " + b"{b: " * 5000 + b"1" + b"}" * 5000 + b"\n", [], "a.b.b"),
    # 3. size and alias expansion
    (3, "billion_laughs_in_description", bomb(), [], "description.a"),
    (3, "fifty_megabyte_file", BASE + b"#" * (50 * 2**20), [], "SCENE: 50 MiB is more than"),
    (3, "alias_bomb_in_groups", scene(groups="  - &g {name: g, shape: triangle, count: 3}\n"
                                             "x: &x [*g, *g, *g, *g, *g, *g, *g, *g, *g, *g]"
                                             + "".join(f"\ny{i}: &y{i} [" + ", ".join(
                                                 [f"*{'x' if i == 0 else f'y{i - 1}'}"] * 10)
                                                 + "]" for i in range(6))),
     [], "y4: expands to more than 1000000 values"),
    # 4. explicit vertices
    (4, "vertices_3d_in_2d_scene", scene(groups="  - agents: [{vertices: [[0,1,0],[1,0,0],"
                                                "[0,0,1]]}]"),
     [], "groups[0].agents[0].vertices: vertices have 3 coordinates, the scene has dimension 2"),
    (4, "ragged_vertices", scene(groups="  - agents: [{vertices: [[0,1],[1],[0.8,-0.5]]}]"),
     [], "groups[0].agents[0].vertices[1]: vertex 1 has 1 coordinate(s), vertex 0 has 2"),
    (4, "vertices_text", scene(groups="  - agents: [{vertices: abc}]"),
     [], "groups[0].agents[0].vertices: expected a list of vertices"),
    (4, "second_agent_wrong_dimension",
     scene(groups="  - agents: [{vertices: [[0,1],[1,0],[0,0]]}, {vertices: [[0,1,2],[1,0,2]]}]"),
     [], "groups[0].agents[1].vertices: vertices have 3 coordinates"),
    # 5. sizes
    (5, "count_1e9", scene(groups="  - {shape: triangle, count: 1000000000}"), [],
     "groups[0].count: the scene needs about"),
    (5, "count_1e300", scene(groups="  - {shape: triangle, count: 1e300}"), [],
     "groups[0].count: the scene needs about"),
    (5, "dimension_1e6", scene("dimension: 1000000"), [], "dimension: must be <= 64"),
    (5, "polygon_1e9", scene(groups="  - {shape: {polygon: 1000000000}, count: 2}"), [],
     "groups[0].shape.polygon: 1000000000 vertices; a polytope may have at most 4096"),
    (5, "hypercube_30", scene("dimension: 30", groups="  - {shape: {hypercube: 30}, count: 2}"),
     [], "groups[0].shape.hypercube: 1073741824 vertices"),
    (5, "simplex_beyond_dimension", scene(groups="  - {shape: {simplex: 100000}, count: 2}"),
     [], "groups[0].shape.simplex: a simplex of dimension 100000 does not fit"),
    (5, "memory_limit_flag_lowers_limit", scene(groups="  - {shape: triangle, count: 100000}"),
     ["--memory-limit", "16M"], "groups[0].count: the scene needs about"),
    # 6. steps and samples
    (6, "dt_1e-300", scene("integrator: {method: rkmk4, dt: 1e-300}"), [],
     "integrator.dt: dt = 1e-300 over t_end = 2 takes 2e+300 steps, more than "
     "integrator.max_steps = 10000000"),
    (6, "t_end_1e12", scene("time: {t_end: 1e12}"), [], "integrator.dt: dt = 0.05 over t_end"),
    (6, "samples_count_1e9", scene("time: {t_end: 2.0, samples: {count: 1e9}}"), [],
     "time.samples.count: must be <= 100000"),
    (6, "samples_every_1e-12", scene("time: {t_end: 2.0, samples: {every: 1e-12}}"), [],
     "time.samples.every: every 1e-12 over t_end = 2 is 2e+12 samples"),
    (6, "t_end_1e-300_adaptive", scene("integrator: {method: adaptive, tolerance: 1e-6}",
                                       "time: {t_end: 1e-300}"), [],
     "time.t_end: must be >= 1e-12, got 1e-300"),
    (6, "cli_dt_1e-300", BASE, ["--dt", "1e-300"], "--dt: dt = 1e-300 over t_end = 2"),
    (6, "explain_dt_1e-300", BASE, ["EXPLAIN", "--dt", "1e-300"], "--dt: dt = 1e-300"),
    # 7. stability analysis inputs
    (7, "kappa_1e300", scene("model: {order: 1, kappa: 1e300}"), [], "model.kappa: must be <="),
    (7, "mass_1e-300", scene("model: {order: 2, mass: 1e-300}"), [],
     "model: the rate (kappa * max s_k/s_i + kappa_2) / m = 1e+300 exceeds"),
    (7, "log_uniform_scales_1e300", scene(groups="  - {shape: triangle, count: 3, scales: "
                                                 "{log_uniform: [1e-300, 1e300]}}"),
     [], "groups[0].scales.log_uniform: scales must lie in [1e-12, 1e+12]"),
    # 8. tolerances
    (8, "tolerance_1e-200", scene("integrator: {method: adaptive, tolerance: 1e-200}"), [],
     "integrator.tolerance: 1e-200 is below 1e-14"),
    (8, "tolerance_1e-30", scene("integrator: {method: adaptive, tolerance: 1e-30}"), [],
     "integrator.tolerance: 1e-30 is below 1e-14"),
    (8, "cli_tolerance_1e-300", BASE, ["-i", "adaptive", "--tolerance", "1e-300"],
     "argument --tolerance: 1e-300 is below 1e-14"),
    # 9. outputs
    (9, "save_into_missing_directory", BASE, ["--save", "/nonexistent/dir/x.npz"],
     "/nonexistent/dir/x.npz: the directory /nonexistent/dir does not exist"),
    (9, "figure_into_missing_directory", BASE, ["--figure", "/nonexistent/dir/x.png"],
     "/nonexistent/dir/x.png: the directory /nonexistent/dir does not exist"),
    # 10. geometry that cannot be represented
    (10, "size_1e300", scene(groups="  - {shape: triangle, count: 3, size: 1e300}"), [],
     "groups[0].size: must be <= 1e+12"),
    (10, "centroid_box_1e308", scene(groups="  - {shape: triangle, count: 3, "
                                            "centroids: {box: [-1e308, 1e308]}}"), [],
     "groups[0].centroids.box[0]: must be within +-1e+12"),
    (10, "points_1e300", scene(groups="  - {shape: triangle, count: 2, centroids: "
                                      "{points: [[0, 0], [1e300, 0]]}}"), [],
     "groups[0].centroids.points[1][0]: must be within +-1e+12"),
    (10, "L_1e300", scene("model: {order: 1, kappa_2: 1.0, L: 1e300}",
                          groups="  - {shape: triangle, count: 2}\n  - {shape: square, "
                                 "count: 2, name: s}"), [], "model.L: must be <= 1e+12"),
    # 11. duplicate keys
    (11, "duplicate_top_key", BASE + b"dimension: 3\n", [],
     "dimension: duplicate key (lines 2 and 9)"),
    (11, "duplicate_nested_key", scene("integrator: {method: rkmk4, dt: 0.05, dt: 0.1}"), [],
     "integrator.dt: duplicate key"),
    # 12. types
    (12, "name_list", scene("name: [1, 2]"), [], "name: expected text, got a list"),
    (12, "group_name_null", scene(groups="  - {name: null, shape: triangle, count: 3}"), [],
     "groups[0].name: no value (null)"),
    (12, "quoted_number", scene('dimension: "2"'), [],
     "dimension: expected a number, got the text '2'"),
    (12, "quoted_exponent", scene('time: {t_end: "1e3"}'), [],
     "time.t_end: expected a number, got the text '1e3'"),
    (12, "boolean_count", scene(groups="  - {shape: triangle, count: true}"), [],
     "groups[0].count: expected a number, got true"),
    # 13. options that would be ignored
    (13, "cli_tolerance_with_fixed_step", BASE, ["--tolerance", "1e-6"],
     "--tolerance: rkmk4 takes fixed steps"),
    (13, "cli_dt_with_adaptive", BASE, ["-i", "adaptive", "--dt", "0.1"],
     "--dt: the adaptive integrator chooses its own steps"),
    (13, "scene_adaptive_with_dt", scene("integrator: {method: adaptive, dt: 0.1}"), [],
     "integrator.dt: the adaptive method chooses its own steps"),
    (13, "scene_fixed_step_with_tolerance", scene("integrator: {method: rkmk4, tolerance: 1e-6}"),
     [], "integrator.tolerance: rkmk4 takes fixed steps"),
    (13, "max_steps_1_fixed_step", scene("integrator: {method: rkmk4, dt: 0.1, max_steps: 1}"),
     [], "integrator.dt: dt = 0.1 over t_end = 2 takes 20 steps, more than "
         "integrator.max_steps = 1"),
    (13, "cli_tolerance_2", BASE, ["-i", "adaptive", "--tolerance", "2"],
     "argument --tolerance: must be in (0, 1), got 2"),
    # 14. wording and key paths
    (14, "directory_as_scene", None, [], "DIR: is a directory, not a scene file"),
    (14, "empty_file", b"", [], "SCENE: empty; a scene is a mapping of keys"),
    (14, "comments_only", b"# nothing\n", [], "SCENE: empty; a scene is a mapping of keys"),
    (14, "groups_as_mapping", scene(groups="  g: {shape: triangle}"),
     [], "groups: expected a list of groups"),
    (14, "polygon_path_prefix", scene(groups="  - {shape: {polygon: 2}, count: 2}"), [],
     "groups[0].shape.polygon: must be >= 3"),
    (14, "coincident_vertices_path", scene(groups="  - agents: [{vertices: [[0,1],[0,1],[1,0]]}]"),
     [], "groups[0].agents[0].vertices: vertices 0 and 1 coincide"),
    (14, "top_level_list", b"- 1\n- 2\n", [], "scene: expected a mapping of keys, got a list"),
    # 16. errors about what was typed: the option, the near miss, the allowed values
    (16, "cli_integrator_unknown", BASE, ["-i", "rk5"],
     "--integrator: unknown integrator 'rk5'; known: etd1, etd2, euler_proj, lie_euler, "
     "lie_heun, lie_verlet, rk4_proj, rkmk4, adaptive, auto"),
    (16, "explain_integrator_near_miss", BASE, ["EXPLAIN", "--integrator", "rkmk5"],
     "--integrator: unknown integrator 'rkmk5'; known: etd1, etd2, euler_proj, lie_euler, "
     "lie_heun, lie_verlet, rk4_proj, rkmk4, adaptive, auto; did you mean 'rkmk4'?"),
    (16, "cli_t_end_past_the_samples_limit", scene("time: {t_end: 2.0, samples: {every: 0.5}}"),
     ["--t-end", "1e300"], "--t-end 1e+300: time.samples.every: every 0.5 over t_end = 1e+300 "
     "is 2e+300 samples, more than the limit of 100000 samples a run"),
    (16, "cli_dt_unstable", scene("time: {t_end: 100.0}"), ["--dt", "10"],
     "--dt: rkmk4 is unstable at dt = 10"),
    (16, "explain_dt_unstable", scene("time: {t_end: 100.0}"), ["EXPLAIN", "--dt", "10"],
     "--dt: rkmk4 is unstable at dt = 10"),
    (16, "key_near_miss_rotation", scene(groups="  - {shape: triangle, count: 3, "
                                                "rotation: uniform}"), [],
     "groups[0].rotation: unknown key; did you mean 'rotations'? (allowed: name, shape, size, "
     "count, centroids, rotations, scales"),
    (16, "key_near_miss_kapa", scene("model: {order: 1, kapa: 2.0}"), [],
     "model.kapa: unknown key; did you mean 'kappa'? (allowed: order, kappa, gamma"),
    (16, "key_far_from_any", scene("model: {order: 1, zzz: 2.0}"), [],
     "model.zzz: unknown key (allowed: order, kappa"),
    (16, "representation_lists_the_allowed", scene("model: {order: 1, representation: angles}"),
     [], "model.representation: unknown rotation representation 'angles'; did you mean "
         "'angle'? (allowed: auto, angle, so3, so3-cayley, so3-exp, matrix)"),
    (16, "scene_integrator_near_miss", scene("integrator: {method: rkmk5, dt: 0.05}"), [],
     "integrator.method: unknown integrator 'rkmk5'; known: etd1, etd2, euler_proj, lie_euler, "
     "lie_heun, lie_verlet, rk4_proj, rkmk4, adaptive, auto; did you mean 'rkmk4'?"),
]

# 15: command-line parse errors: (test id, argv, expected start of the message)
PARSE_CASES = [
    ("no_arguments", [], "the following arguments are required: COMMAND (see `polymatch --help`)"),
    ("bad_dt", ["simulate", "congruent_triangles", "--dt", "fast"],
     "argument --dt: expected a number, got 'fast' (see `polymatch simulate --help`)"),
    ("unknown_option", ["simulate", "congruent_triangles", "--frobnicate"],
     "unrecognized arguments: --frobnicate"),
    ("run_bad_dt", ["run", "congruent_triangles", "--dt", "-1"], "argument --dt:"),
    ("unknown_command", ["simulte"], "argument COMMAND: invalid choice: 'simulte'"),
    ("bad_memory_limit", ["simulate", "congruent_triangles", "--memory-limit", "lots"],
     "argument --memory-limit: expected a size such as 512M or 8G"),
]
