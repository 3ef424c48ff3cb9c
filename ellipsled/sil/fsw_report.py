"""What only the flight software knows at the end of a run, as plain JSON values, and the
allocation samples for the offline optimality check. The FSW process writes them to
fsw.json, the batch runner keeps them in memory; ellipsled/runlib.py judges them alike.
"""
from __future__ import annotations

from fsw.flightsoftware import FlightSoftware


def fsw_report(fsw: FlightSoftware, slips: int, alloc_samples: list) -> dict:
    """What only the FSW knows, as plain JSON values (the SIL FSW process writes this)."""
    return {
        "detections": [{"jet": int(d["jet"]), "kind": d["kind"], "t_s": round(float(d["t_s"]), 6),
                        **({"eta_hat": round(float(d["eta_hat"]), 4)} if d.get("eta_hat") is not None else {})}
                       for d in fsw.fdir.detections],
        "reconfig_times_s": list(fsw.reconfig_times),
        "propellant_kg": float(fsw.driver.propellant_kg),
        "jet_pulses_per_jet": [int(x) for x in fsw.driver.pulses],
        "cycle_slips": int(slips),
        "alloc_modulated": int(fsw.dutycycle.modulated_cycles),
        "events": fsw.events.total,
        "alloc_samples": alloc_samples,
        **({"guidance": fsw.entry.stats()} if fsw.entry is not None else {}),
    }


def alloc_sample(fsw: FlightSoftware) -> dict:
    """One allocator demand, its health and its objective, for an offline optimality check."""
    hl = fsw.allocator_health()
    return {"tau_d": fsw.dutycycle.demand_B.tolist(), "state": hl.state.tolist(), "eta": hl.eta.tolist(),
            "inhibited": hl.inhibited.tolist(), "objective": float(fsw.allocator.objective)}
