"""Every catalogue motor in MuJoCo against its datasheet (issue 33, item 2): the table in docs/models.md.

Each motor is fitted to its datasheet's four figures (motors.datasheet, with its dry share of the no-load friction),
put on a wheel in MuJoCo at the product's 1 ms step, and measured as a datasheet is measured (motors.dyno): no-load
speed and current at the rated voltage, the stall torque and current where the loaded torque-speed line reaches zero
speed. Targets: speeds and stall torques within 2 %, currents within 10 %. It also prints each fit's gearbox
efficiency η, dry friction τ0, viscous b_M, the dead band R·τ0/K below which the motor does not break away, and the
no-load power U·I_0 that every lap's energy pays per motor.

  python benchmarks/bench_motors.py [--quick] [--json]

``--quick``: the default motor and the original 3pi's only (for CI: the script cannot rot).
"""

from __future__ import annotations

import argparse
import json
import sys

from motors.catalogue import CATALOGUE
from motors.datasheet import RPM
from motors.dyno import measured_points, wheel_in_free_air

SPEED_TORQUE_PERCENT, CURRENT_PERCENT = 2.0, 10.0
QUICK = ("pololu-mp-6v-30", "pololu-3pi-30")


def row(name: str) -> dict:
    d = CATALOGUE[name]
    m = d.constants()
    got = measured_points(wheel_in_free_air(m), d.voltage, d.stall_torque)
    sheet = {"no_load_speed": d.no_load_speed, "no_load_current": d.no_load_current,
             "stall_torque": d.stall_torque, "stall_current": d.stall_current}
    error = {k: 100.0 * (got[k] / sheet[k] - 1.0) for k in sheet}
    return {"motor": name, "voltage": d.voltage, "datasheet": sheet, "measured": got, "error_percent": error,
            "no_load_current_assumed": d.no_load_current_assumed, "efficiency": m.efficiency,
            "friction_Nm": m.friction, "b_M": m.b_M, "dead_band_V": m.R_M * m.friction / m.K,
            "no_load_power_W": d.voltage * got["no_load_current"],
            "ok": all(abs(error[k]) <= SPEED_TORQUE_PERCENT for k in ("no_load_speed", "stall_torque"))
            and all(abs(error[k]) <= CURRENT_PERCENT for k in ("no_load_current", "stall_current"))}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0],
                                     formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    parser.add_argument("--quick", action="store_true", help="two motors only (CI)")
    parser.add_argument("--json", action="store_true", help="one JSON document on stdout")
    args = parser.parse_args(argv)
    rows = [row(n) for n in (QUICK if args.quick else sorted(CATALOGUE))]
    if args.json:
        print(json.dumps({"rows": rows, "all_within_targets": all(r["ok"] for r in rows)}))
    else:
        print(f"{'motor':<22} {'U':>5} {'rpm sheet/model':>16} {'I0 mA':>14} {'stall mN·m':>16} {'stall mA':>14} "
              f"{'eta':>6} {'tau0 uN·m':>9} {'b_M nN·m·s':>10} {'dead V':>7} {'P0 W':>6}")
        for r in rows:
            s, g = r["datasheet"], r["measured"]
            i0 = f"{s['no_load_current'] * 1e3:.0f}{'*' if r['no_load_current_assumed'] else ''}"
            print(f"{r['motor']:<22} {r['voltage']:>5g} {s['no_load_speed'] / RPM:>7.0f}/{g['no_load_speed'] / RPM:<8.1f} "
                  f"{i0:>6}/{g['no_load_current'] * 1e3:<7.1f} {s['stall_torque'] * 1e3:>7.2f}/{g['stall_torque'] * 1e3:<8.2f} "
                  f"{s['stall_current'] * 1e3:>6.0f}/{g['stall_current'] * 1e3:<7.1f} {r['efficiency']:>6.3f} "
                  f"{r['friction_Nm'] * 1e6:>9.1f} {r['b_M'] * 1e9:>10.2f} {r['dead_band_V']:>7.3f} "
                  f"{r['no_load_power_W']:>6.3f}{'' if r['ok'] else '  OFF TARGET'}")
        worst = {k: max(abs(r["error_percent"][k]) for r in rows) for k in rows[0]["error_percent"]}
        print("largest error [%]: " + ", ".join(f"{k} {v:.2f}" for k, v in worst.items())
              + f" (targets: speed and stall torque {SPEED_TORQUE_PERCENT:g} %, currents {CURRENT_PERCENT:g} %); "
              "* no-load current assumed (the catalogue says whose)")
    return 0 if all(r["ok"] for r in rows) else 1


if __name__ == "__main__":
    sys.exit(main())
