"""Benchmark: the float64 regressor against Pinocchio, and the observation matrix W (not run by CI).

1. Regressor per sample, PUMA 560 and a 7R arm, batches of 1,000 / 10,000 / 50,000 random
   states, measured side by side in this process: ours (the generated straight-line code,
   :mod:`baseparams.dynamics.codegen`, generated once per mechanism; the time to generate it
   is printed apart), the generic vectorised numpy path it replaced, and Pinocchio's
   ``computeJointTorqueRegressor`` called sample after sample into one preallocated array
   (the way a Python user batches it), the two taking turns; the ratio of their best wall
   times and of their best CPU times (steadier on a loaded machine). Target: ours /
   Pinocchio <= 1.0.
2. SLA suspension W (200 samples, loop closure included): float64, cold (first call in the
   process: generates the code) and warm; warm through the general per-stage Newton
   (``evaluator.BATCHED_NEWTON = False``, the method the batched continuation replaced) in
   the same run, as the yardstick, with the ratio; the kinematics frames computed afresh
   (what every W paid before they were cached); arb at 30, 100 and 500 digits.

Pinocchio is optional (``import pinocchio``); without it the yardstick column says so.
``--levels``: also the level-scheduled form of the generated code, measured and not kept
(codegen._numpy_kernel says why). ``--previous FILE``: another version of core/dynamics/codegen.py (for example
``git show 5c97906:core/dynamics/codegen.py > /tmp/codegen_before.py``) timed in the same
rounds, as one more column, to measure a change of the generated code in one run.

Run: python benchmarks/bench_regressor.py [--repeat R] [--quick] [--previous FILE] [--levels] [--regressor-only]
"""

import argparse
import importlib.util
import platform
import sys
import time
import tracemalloc

import numpy as np
import sympy

from baseparams.dynamics import codegen, evaluator
from baseparams.dynamics.evaluator import Evaluator
from baseparams.dynamics.regressor import tree_regressor_array
from baseparams.dynamics.trajectory import observation_matrix
from baseparams.io.loader import parse_mechanism, resolve
from baseparams.kinematics import tree
from baseparams.model import generate
from baseparams.numeric.backends import Arb, Float64

try:
    import pinocchio as pin
except ImportError:          # the yardstick is optional
    pin = None

SEVEN_R_SEED = 7             # generate.serial_chain(7, bodies=7, types="R"): the 7R arm


def best_of(repeat, fn):
    times, result = [], None
    for _ in range(repeat):
        start = time.perf_counter()
        result = fn()
        times.append(time.perf_counter() - start)
    return min(times), result


def best_cpu_of(repeat, fn):
    """Best process CPU time of ``repeat`` calls: on a loaded machine the wall time also
    counts the other jobs' share of the cores."""
    times = []
    for _ in range(repeat):
        start = time.process_time()
        fn()
        times.append(time.process_time() - start)
    return min(times)


def peak_memory_mb(fn):
    tracemalloc.start()
    fn()
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    return peak / 2 ** 20


def _se3(rot, point):
    return pin.SE3(np.array(rot, dtype=float), np.array(point, dtype=float))


def pinocchio_model(mechanism):
    """A Pinocchio model with the mechanism's kinematics (open chains and trees of 1-coordinate
    R and P joints): joint j placed at its parent frame in the parent's *joint* frame, which
    is the parent body's frame moved by its child frame (body = joint frame x child^-1).
    Inertias are the file's own, about each body's origin (when the child frames are
    identities, Pinocchio's dynamic parameters are ours, in its order m, mc, Ixx Ixy Iyy Ixz
    Iyz Izz: :func:`pin_columns`)."""
    backend = Float64()
    model = pin.Model()
    model.gravity.linear = np.array(mechanism.numeric_gravity(backend), dtype=float)
    joint_of, child_of = {0: 0}, {0: pin.SE3.Identity()}
    bodies = {b.label: b for b in mechanism.bodies}
    for edge in mechanism.tree:
        joint = edge.joint
        if edge.reversed or joint.type.name not in ("R", "P"):
            raise ValueError("pinocchio_model: open chains of R and P joints only")
        fp = _se3(*mechanism.numeric_frame(joint.parent_frame, backend))
        fc = _se3(*mechanism.numeric_frame(joint.child_frame, backend))
        placement = child_of[joint.parent] * fp       # parent joint frame -> this joint's frame
        kind = pin.JointModelRZ() if joint.type.name == "R" else pin.JointModelPZ()
        jid = model.addJoint(joint_of[joint.parent], kind, placement, f"j{joint.child}")
        joint_of[joint.child], child_of[joint.child] = jid, fc
        inertia = pin.Inertia.FromDynamicParameters(np.array(_pin_parameters(bodies[joint.child]), dtype=float))
        model.appendBodyToJoint(jid, inertia, fc.inverse())          # the body frame in the joint frame
    return model


def _pin_parameters(body):
    """m, mx, my, mz, Ixx, Ixy, Iyy, Ixz, Iyz, Izz of a body (Pinocchio's order), or a
    valid placeholder when the file has none."""
    values = body.inertia
    if values is None:
        return [1.0, 0.1, 0.0, 0.0, 0.1, 0.0, 0.1, 0.0, 0.0, 0.1]
    m, mx, my, mz, ixx, ixy, ixz, iyy, iyz, izz = (float(values[k]) for k in range(10))
    return [m, mx, my, mz, ixx, ixy, iyy, ixz, iyz, izz]


PIN_ORDER = (0, 1, 2, 3, 4, 5, 7, 6, 8, 9)   # ours (m mx my mz Ixx Ixy Ixz Iyy Iyz Izz) -> Pinocchio's


def pin_columns(bodies):
    """Column permutation taking our regressor's columns to Pinocchio's."""
    return [10 * b + k for b in range(bodies) for k in PIN_ORDER]


def states(n, count, seed=0):
    rng = np.random.default_rng(seed)
    return [rng.uniform(-2.0, 2.0, (count, n)) for _ in range(3)]


def ours(mechanism, q, qd, qdd):
    return codegen.tree_regressor(mechanism, list(q.T), list(qd.T), list(qdd.T))


def generic(mechanism, q, qd, qdd):
    ev = Evaluator(mechanism, Float64())
    sample = ev.sample(list(q.T), list(qd.T), list(qdd.T))
    return tree_regressor_array(sample.kin, sample.states, sample.qdd)


def pinocchio_batch(model, data, q, qd, qdd):
    out = np.empty((len(q), model.nv, 10 * (model.njoints - 1)))
    for i in range(len(q)):
        out[i] = pin.computeJointTorqueRegressor(model, data, q[i], qd[i], qdd[i])
    return out


def interleaved(repeat, fns):
    """Best wall and best CPU time of each of ``fns`` over ``repeat`` rounds, the functions
    taking turns within a round, so that a change of load hits all of them alike."""
    wall = {k: float("inf") for k in fns}
    cpu = dict(wall)
    for _ in range(repeat):
        for k, fn in fns.items():
            w, c = time.perf_counter(), time.process_time()
            fn()
            wall[k] = min(wall[k], time.perf_counter() - w)
            cpu[k] = min(cpu[k], time.process_time() - c)
    return wall, cpu


def level_schedule(mechanism):
    """The idea measured and not kept (codegen._numpy_kernel): the traced regressor as
    levels, each kind of operation of a level one numpy call on a (nodes, samples) array,
    operands sliced when contiguous and gathered otherwise. Returns a function of
    (q, qd, qdd) as (n, samples) arrays -> K (samples, n, p) and the number of calls."""
    graph, (kernel,) = codegen.trace(mechanism, ("regressor",))
    writes, live, _ = codegen._liveness(graph, kernel)
    ops, row, level, groups = graph.ops, {}, {}, {}
    for i, op in enumerate(ops):
        if live[i] and op[0] == "in":
            row[i], level[i] = len(row), 0
        elif live[i]:
            level[i] = 1 + max(level[x] for x in codegen._operands(op))
            kinds = tuple("n" if isinstance(x, int) else "c" for x in op[1:] if x is not None)
            groups.setdefault((level[i], op[0], kinds), []).append(i)
    ufunc = {"add": np.add, "sub": np.subtract, "mul": np.multiply, "div": np.divide,
             "neg": np.negative, "cos": np.cos, "sin": np.sin}
    steps = []
    for key in sorted(groups, key=lambda k: k[0]):
        members = sorted(groups[key], key=lambda i: row.get(ops[i][1], -1))
        start = len(row)
        row.update((i, start + k) for k, i in enumerate(members))
        operands = []
        for pos, kind in enumerate(key[2], start=1):
            if kind == "c":
                operands.append(("c", np.array([[float(sympy.N(ops[i][pos][1], 30))] for i in members])))
                continue
            rows = np.array([row[ops[i][pos]] for i in members])
            contiguous = np.all(np.diff(rows) == 1)
            operands.append(("s", slice(rows[0], rows[-1] + 1)) if contiguous else ("g", rows))
        steps.append((ufunc[key[1]], slice(start, start + len(members)), operands))
    inputs = [(row[i], ops[i][1][1]) for i in row if ops[i][0] == "in"]
    layout = codegen.layouts(kernel)["K"]
    outputs = np.array([row[i] for i in layout.nodes])
    calls = len(steps) + sum(kind == "g" for _, _, ops_ in steps for kind, _ in ops_)

    def evaluate(q, qd, qdd, chunk=1000):            # 1 000: its best chunk, measured
        count = q.shape[1]
        k = np.zeros((count, layout.shape[0] * layout.shape[1]))
        for start in range(0, count, chunk):
            arrays = {"q": q[:, start:start + chunk], "qd": qd[:, start:start + chunk],
                      "qdd": qdd[:, start:start + chunk]}
            work = np.empty((len(row), arrays["q"].shape[1]))
            for r, (name, j) in inputs:
                work[r] = arrays[name][j]
            for fn, out, operands in steps:
                args = [v if kind == "c" else work[v] if kind == "s" else np.take(work, v, axis=0, mode="clip")
                        for kind, v in operands]
                fn(*args, out=work[out])
            k[start:start + chunk, list(layout.slots)] = work[outputs].T
        return k.reshape((count,) + layout.shape)
    return evaluate, calls


def levels_table(name, mechanism, batches, repeat):
    evaluate, calls = level_schedule(mechanism)
    print(f"\n{name}, level-scheduled (not kept): {calls} numpy calls per chunk")
    print(f"{'samples':>8} {'ours us/sample':>15} {'levels':>9} {'levels/ours (CPU)':>18}")
    for count in batches:
        q, qd, qdd = states(len(mechanism.coordinates), count)
        x = (np.ascontiguousarray(q.T), np.ascontiguousarray(qd.T), np.ascontiguousarray(qdd.T))
        assert np.allclose(evaluate(*x), ours(mechanism, q, qd, qdd), rtol=1e-12, atol=1e-9)
        wall, cpu = interleaved(repeat, {"ours": lambda: ours(mechanism, q, qd, qdd), "levels": lambda: evaluate(*x)})
        print(f"{count:8d} {wall['ours'] / count * 1e6:15.2f} {wall['levels'] / count * 1e6:9.2f}"
              f" {cpu['levels'] / cpu['ours']:18.2f}")


def load_previous(path):
    """A codegen module from another version's source file (its own caches)."""
    spec = importlib.util.spec_from_file_location("codegen_previous", path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module          # dataclasses look their module up
    spec.loader.exec_module(module)
    return module


def regressor_table(name, mechanism, batches, repeat, previous=None):
    n = len(mechanism.coordinates)
    start = time.perf_counter()
    module = codegen.compiled(mechanism, "regressor")
    print(f"\n{name}: {n} coordinates, {len(mechanism.parameters)} parameters; code generated and "
          f"compiled in {time.perf_counter() - start:.2f} s (once per mechanism and process); "
          f"{module['_WORK']['_tree_regressor']} work rows")
    model = data = None
    if pin is not None:
        model = pinocchio_model(mechanism)
        data = model.createData()
    if previous is not None:
        previous.compiled(mechanism, "regressor")
    print(f"{'samples':>8} {'ours us/sample':>15} {'generic numpy':>14} {'Pinocchio':>10} {'ours/Pinocchio':>15}"
          f" {'(CPU time)':>11}" + (f" {'previous':>9} {'ours/previous (CPU)':>20}" if previous else ""))
    for count in batches:
        q, qd, qdd = states(n, count)
        t_gen, k0 = best_of(max(1, repeat // 2), lambda: generic(mechanism, q, qd, qdd))
        fns = {"ours": lambda: ours(mechanism, q, qd, qdd)}
        if model is not None:
            fns["pin"] = lambda: pinocchio_batch(model, data, q, qd, qdd)
        if previous is not None:
            fns["previous"] = lambda: previous.tree_regressor(mechanism, list(q.T), list(qd.T), list(qdd.T))
        wall, cpu = interleaved(repeat, fns)
        k = ours(mechanism, q, qd, qdd)
        assert np.allclose(k, k0, rtol=1e-12, atol=1e-12 * np.abs(k0).max())
        line = f"{count:8d} {wall['ours'] / count * 1e6:15.2f} {t_gen / count * 1e6:14.2f}"
        if model is not None:
            line += (f" {wall['pin'] / count * 1e6:10.2f} {wall['ours'] / wall['pin']:15.2f}"
                     f" {cpu['ours'] / cpu['pin']:11.2f}")
        else:
            line += f" {'(absent)':>10} {'-':>15} {'-':>11}"
        if previous is not None:
            assert np.allclose(fns["previous"](), k0, rtol=1e-12, atol=1e-12 * np.abs(k0).max())
            line += (f" {wall['previous'] / count * 1e6:9.2f} {wall['ours'] / wall['previous']:9.2f}"
                     f" ({cpu['ours'] / cpu['previous']:.2f})")
        print(line)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--quick", action="store_true", help="batches of 1,000 and 10,000 only; no arb")
    parser.add_argument("--previous", metavar="FILE", help="another codegen.py, timed in the same rounds")
    parser.add_argument("--regressor-only", action="store_true", help="part 1 only (no SLA W)")
    parser.add_argument("--levels", action="store_true", help="also time the level-scheduled form (not kept)")
    args = parser.parse_args()
    previous = load_previous(args.previous) if args.previous else None
    print(f"machine: {platform.processor() or platform.machine()}, python {platform.python_version()}, "
          f"numpy {np.__version__}, Pinocchio {pin.__version__ if pin else 'absent (pip install pin)'}")
    batches = (1000, 10000) if args.quick else (1000, 10000, 50000)
    regressor_table("PUMA 560", resolve("puma560"), batches, args.repeat, previous)
    seven = parse_mechanism(generate.serial_chain(SEVEN_R_SEED, bodies=7, types="R"))
    regressor_table(f"7R arm (generate.serial_chain({SEVEN_R_SEED}, bodies=7, types='R'))", seven, batches,
                    args.repeat, previous)
    if args.levels:
        levels_table("PUMA 560", resolve("puma560"), batches, args.repeat)
        levels_table("7R arm", seven, batches, args.repeat)
    if args.regressor_only:
        return

    sla = resolve("sla_suspension")
    print("\nSLA suspension, W = 400 x 70 (200 samples, 2 dof, loop closure included)")
    print(f"{'arithmetic':>16} {'time (s)':>10} {'peak MB':>8}  closure residual")
    start = time.perf_counter()
    observation_matrix(sla, Float64())
    print(f"{'float64 (cold)':>16} {time.perf_counter() - start:10.3f}  (generates the closure code)")
    start = time.perf_counter()
    codegen.compiled(sla, "regressor")      # 200 samples alone would not generate it (GENERATE_AT)
    print(f"{'regressor code':>16} {time.perf_counter() - start:10.3f}  (generated; warm = both compiled)")
    t, (w, _) = best_of(args.repeat, lambda: observation_matrix(sla, Float64()))
    cpu = best_cpu_of(args.repeat, lambda: observation_matrix(sla, Float64()))
    print(f"{'float64 (warm)':>16} {t:10.3f} {peak_memory_mb(lambda: observation_matrix(sla, Float64())):8.1f}"
          f"  (CPU {cpu:.3f} s)")
    evaluator.BATCHED_NEWTON = False
    t_general, (w_general, _) = best_of(args.repeat, lambda: observation_matrix(sla, Float64()))
    cpu_general = best_cpu_of(args.repeat, lambda: observation_matrix(sla, Float64()))
    evaluator.BATCHED_NEWTON = True
    assert np.abs(w - w_general).max() <= 1e-10 * np.abs(w_general).max()
    print(f"{'general Newton':>16} {t_general:10.3f}           (CPU {cpu_general:.3f} s; yardstick, same run; the "
          f"same W to {np.abs(w - w_general).max() / np.abs(w_general).max():.1e} relative)")
    print(f"{'ratio':>16} {t / t_general:10.3f}           (CPU {cpu / cpu_general:.3f}) batched continuation / "
          f"general Newton")

    def fresh_frames():
        tree._PREPARED.pop(sla, None)
        return tree.TreeKinematics(sla, Float64())

    t_frames, _ = best_of(args.repeat, fresh_frames)
    print(f"{'frames afresh':>16} {t_frames:10.3f}  (the kinematics frames through sympy: once per "
          f"mechanism and process now, at every W before)")
    if args.quick:
        return
    print(f"{'':>16} {'':>10} {'':>8}  yardstick (same run): the generic kinematics for the closure terms "
          f"(evaluator.SCALAR_CLOSURE = False)")
    for digits in (30, 100, 500):
        repeat = args.repeat if digits < 500 else 1
        t, (_, info) = best_of(repeat, lambda: observation_matrix(sla, Arb(digits)))
        mem = peak_memory_mb(lambda: observation_matrix(sla, Arb(digits)))
        evaluator.SCALAR_CLOSURE = False
        t_generic, _ = best_of(repeat, lambda: observation_matrix(sla, Arb(digits)))
        evaluator.SCALAR_CLOSURE = True
        print(f"{f'arb {digits}':>16} {t:10.3f} {mem:8.1f}  {info['closure_residual']}; generic closure "
              f"{t_generic:.3f} s, ratio {t / t_generic:.2f}")


if __name__ == "__main__":
    main()
