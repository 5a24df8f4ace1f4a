"""Named gearmotors with their datasheet figures, for ``--motor NAME``, ``--grid motor.model=A,B`` and the choice
of a motor for a robot (:mod:`motors.choice`). Figures at the gearbox output, at the rated 6 V.

Pololu Micro Metal Gearmotors, current generation, with low-, medium- and high-power windings (LP, MP, HP: precious
metal brushes; HPCB: carbon brushes, not the same figures as HP). Each entry cites where its figures come from:
the LP rows are Pololu's datasheet (Rev 2.0, May 2018); the MP, HP and HPCB rows are Pololu's product and specs
pages as quoted by third-party copies (this machine cannot reach pololu.com), so they are as good as those copies.
Left out: LP 10:1 (its printed stall torque × no-load speed exceeds U × I_stall, which no DC motor can do; the
datasheet row has no column header there), and rows whose speed, stall torque or stall current were not found
(HP 10:1, 75:1, 150:1; MP 10:1, 150:1; HPCB 100:1).

Every entry fits the model of :mod:`motors.datasheet` exactly: its gearbox efficiency comes out between 0.51
(LP 100:1) and 0.79 (the 3pi's), its K positive, so no entry's figures contradict each other (LP 10:1, left out
above, is the one that would). The fit needs a no-load current; HP 50:1 and HP 100:1 have none on the copies
read here. The rule: a ratio without one takes its motor family's published no-load current
(``FAMILY_NO_LOAD_CURRENT``: the no-load current is mostly the motor's own drag, and within a family it barely
moves with the ratio: LP 20 mA at every ratio here, MP 70 mA at 50:1 to 100:1, HPCB 150 mA at 30:1 to 75:1), here
HP 30:1's 0.1 A; the entry's source says so, and ``no_load_current_assumed`` marks it.
The 15:1 HPCB row is Pololu's own 3pi+ 32U4 User's Guide (the Hyper Edition's motor), read here; ``pololu-3pi-30``
is the original 3pi's motor as the 3pi Robot User's Guide tabulates it (at its 9.25 V motor supply).

Inductance and rotor inertia are not published: every entry uses the default motor's assumptions (0.5 mH,
2e-9 kg·m², typical of 10 mm-class brushed motors), as :data:`POLOLU_MP_6V_30_1` does.
"""

from __future__ import annotations

from motors.datasheet import POLOLU_MP_6V_30_1, RPM, Datasheet

KG_MM = 9.80665e-3  # [N·m] per [kg·mm]
OZ_IN = 0.00706155183333  # [N·m] per [oz·in]


FAMILY_NO_LOAD_CURRENT = {"HP": 0.1}  # [A] at 6 V: HP 6V 30:1 (#2212), for HP ratios whose copies print none


def _pololu(gear: float, rpm: float, no_load_a: float | None, stall_kg_mm: float, stall_a: float, source: str) -> Datasheet:
    assumed = no_load_a is None
    if assumed:
        family = source.split()[0]
        no_load_a = FAMILY_NO_LOAD_CURRENT[family]
        source += f"; no-load current not published there: the {family} family's {no_load_a * 1000:g} mA assumed"
    return Datasheet(voltage=6.0, stall_torque=stall_kg_mm * KG_MM, stall_current=stall_a, no_load_speed=rpm * RPM,
                     no_load_current=no_load_a, gear=gear, inductance=POLOLU_MP_6V_30_1.inductance,
                     rotor_inertia=POLOLU_MP_6V_30_1.rotor_inertia, source=source, no_load_current_assumed=assumed)


CATALOGUE: dict[str, Datasheet] = {
    "pololu-mp-6v-30": POLOLU_MP_6V_30_1,  # the default robot's motor (3pi+ 32U4 Standard Edition)
    "pololu-lp-6v-30": _pololu(29.86, 450, 0.02, 2.9, 0.36, "LP 6V 30:1 (#993); Pololu Micro Metal Gearmotors datasheet Rev 2.0 (May 2018), performance summary"),
    "pololu-lp-6v-50": _pololu(51.45, 270, 0.02, 4.4, 0.36, "LP 6V 50:1 (#1098); Pololu Micro Metal Gearmotors datasheet Rev 2.0 (May 2018), performance summary"),
    "pololu-lp-6v-75": _pololu(75.81, 180, 0.02, 6.4, 0.36, "LP 6V 75:1 (#2360); Pololu Micro Metal Gearmotors datasheet Rev 2.0 (May 2018), performance summary"),
    "pololu-lp-6v-100": _pololu(100.37, 130, 0.02, 7.4, 0.36, "LP 6V 100:1 (#992); Pololu Micro Metal Gearmotors datasheet Rev 2.0 (May 2018), performance summary"),
    "pololu-lp-6v-150": _pololu(150.58, 90, 0.02, 11, 0.36, "LP 6V 150:1 (#1097); Pololu Micro Metal Gearmotors datasheet Rev 2.0 (May 2018), performance summary"),
    "pololu-mp-6v-50": _pololu(51.45, 420, 0.07, 5.4, 0.67, "MP 6V 50:1 (#2365); https://www.pololu.com/product/2365/specs, as quoted by a third-party copy (not checked against pololu.com here)"),
    "pololu-mp-6v-75": _pololu(75.81, 290, 0.07, 7.8, 0.67, "MP 6V 75:1 (#5137); https://www.pololu.com/product/5137, as quoted by a third-party copy (not checked against pololu.com here)"),
    "pololu-mp-6v-100": _pololu(100.37, 220, 0.07, 9.4, 0.67, "MP 6V 100:1 (#2367); https://www.pololu.com/product/2367/specs, as quoted by a third-party copy (not checked against pololu.com here)"),
    "pololu-hp-6v-30": _pololu(29.86, 1000, 0.1, 5.7, 1.6, "HP 6V 30:1 (#2212); https://www.pololu.com/category/60/micro-metal-gearmotors, as quoted by a third-party copy (not checked against pololu.com here)"),
    "pololu-hp-6v-50": _pololu(51.45, 590, None, 8.6, 1.6, "HP 6V 50:1 (#998); https://www.pololu.com/category/60/micro-metal-gearmotors, as quoted by a third-party copy (not checked against pololu.com here)"),
    "pololu-hp-6v-100": _pololu(100.37, 310, None, 17, 1.6, "HP 6V 100:1 (#1101); https://www.pololu.com/category/60/micro-metal-gearmotors, as quoted by a third-party copy (not checked against pololu.com here)"),
    "pololu-hpcb-6v-30": _pololu(29.86, 1100, 0.15, 4.5, 1.5, "HPCB 6V 30:1 (#3072); https://www.pololu.com/product/3072/specs, as quoted by a third-party copy (not checked against pololu.com here)"),
    "pololu-hpcb-6v-50": _pololu(51.45, 650, 0.15, 7.4, 1.5, "HPCB 6V 50:1 (#3063); https://www.pololu.com/file/0J1487/pololu-micro-metal-gearmotors-rev-6-2.pdf, as quoted by a third-party copy (not checked against pololu.com here)"),
    "pololu-hpcb-6v-75": _pololu(75.81, 430, 0.15, 11, 1.5, "HPCB 6V 75:1 (#3074); https://www.pololu.com/product/3074/specs, as quoted by a third-party copy (not checked against pololu.com here)"),
    # the exact ratio of Pololu's "15:1" is not on that page: 15 nominal (only the reflected rotor inertia uses it)
    "pololu-hpcb-6v-15": _pololu(15.0, 2100, 0.1, 2.5, 1.5, "HPCB 6V 15:1, the 3pi+ 32U4 Hyper Edition's motor; Pololu 3pi+ 32U4 User's Guide, section 5.3 Motors (https://www.pololu.com/docs/0J83/5.3): 2100 RPM, 100 mA; 0.25 kg·cm, 1.5 A at 6 V"),
    # the original 3pi's own motors, as its guide tabulates them; the 3pi drives them from a regulated 9.25 V
    "pololu-3pi-30": Datasheet(voltage=9.25, stall_torque=6.0 * OZ_IN, stall_current=0.54, no_load_speed=700 * RPM,
                               no_load_current=0.06, gear=30.0, inductance=POLOLU_MP_6V_30_1.inductance,
                               rotor_inertia=POLOLU_MP_6V_30_1.rotor_inertia,
                               source="the original 3pi's 30:1 micro metal gearmotors; Pololu 3pi Robot User's Guide, "
                               "section 5.c Motors and Gearboxes (https://www.pololu.com/docs/0J21/5.c): 700 rpm and "
                               "60 mA free-running, 6 oz·in and 540 mA stall; read as figures at the 3pi's regulated "
                               "9.25 V motor supply (section 1: motors at a regulated 9.25 V, up to 100 cm/s)"),
}

# Pololu's 3pi+ 32U4 editions differ in their motors (3pi+ 32U4 User's Guide, section 5.3,
# https://www.pololu.com/docs/0J83/5.3): Turtle 75:1 LP, Standard 30:1 MP, Hyper 15:1 HPCB (top speeds 0.4, 1.5 and
# ~4 m/s; Pololu recommends keeping the Hyper's motors below 50 % speed).
EDITIONS: dict[str, str] = {"3pi+-turtle": "pololu-lp-6v-75", "3pi+-standard": "pololu-mp-6v-30",
                            "3pi+-hyper": "pololu-hpcb-6v-15"}
CATALOGUE.update({edition: CATALOGUE[motor] for edition, motor in EDITIONS.items()})


def names() -> list[str]:
    return sorted(CATALOGUE)
