"""The ``[flow]`` step of ``petgap run``: the leakage of each non-adhesive contact step.

After a step is solved, :func:`flow_of_step` solves the Reynolds equation on its gap
(:func:`petgap.flow.leakage_of`), logs its progress and verdict, and
:func:`write_flow` stores it in the step's group of the result file: the scalars as
``flow.*`` attributes (leak rate, transmissivity, flow factor, percolation, the KSP
status) and the maps ``flow_pressure``, ``flow_flux_x`` and ``flow_flux_y`` beside the
gap.  Adhesive steps get none (the scene refuses a flow whose every step is adhesive;
in the paper's protocol the flow runs on the non-adhesive reference chain).
"""
import time

from petgap.flow import leakage_of

#: The fields a flow step writes, in order.
FLOW_FIELDS = ("flow_pressure", "flow_flux_x", "flow_flux_y")


def flow_of_step(model, step, solution, log, every=5.0):
    """The :class:`petgap.flow.Leakage` of a solved step, or None (collective)."""
    flow = model.scene.flow
    if flow.kind == "none" or step.adhesive:
        return None
    last = [time.perf_counter()]

    def monitor(iteration, norm):
        now = time.perf_counter()
        if now - last[0] >= every:
            last[0] = now
            log.info("  step %d flow: iteration %d, residual %.3e", step.index, iteration, norm)

    result = leakage_of(model.problem_of(step), solution, viscosity=flow.viscosity,
                        pressure_drop=flow.pressure_drop, direction=flow.direction,
                        options=model.options, monitor=monitor)
    log_flow(log, step.index, result)
    return result


def log_flow(log, index, result):
    """The verdict of a flow solve, on rank 0's log."""
    perc = result.percolation
    if result.reason == "no_percolation":
        log.info("  step %d flow: no leak: %s", index, result.message)
        return
    status = "converged" if result.converged else f"NOT converged ({result.reason})"
    log.info("  step %d flow %s after %d iterations (%s, %.2f s): leak rate %.6g, "
             "transmissivity %.6g, flow factor %.5g, open %.4g %% (largest cluster %.4g %%), "
             "mass balance %.1e", index, status, result.iterations, result.pc_type,
             result.solve_time, result.leak_rate, result.transmissivity, result.flow_factor,
             100 * perc.open_fraction, 100 * perc.largest_fraction, result.conservation)
    if not result.converged:
        log.warning("step %d: the flow solve did not converge (%s); stored with "
                    "flow.converged = False", index, result.reason)


def flow_units(units):
    """The unit labels of the flow fields: pressure, and the flux per width (length^2
    per time, the time being the unit of viscosity over that of pressure)."""
    return dict(units, flux=f"({units['length']})^2 / time")


def write_flow(result_file, grid, group, leakage, units):
    """Store a step's flow in its group (collective): attributes and the three maps."""
    if leakage is None:
        return
    result_file.set_attrs(group, {"flow": leakage.scalars()})
    labels = flow_units(units)
    maps = (leakage.pressure, leakage.flux[0], leakage.flux[1])
    for name, field in zip(FLOW_FIELDS, maps):
        result_file.write_field(name, grid, field, group=group, units=labels)
