"""Decodes pyModeS's Comm-B sample replies with pyModeS itself, for
tests/commb_pymodes.rs: one JSON line per row (time, address, frame,
pyModeS's register or candidates, its fields), in the row order.

Usage: commb_reference.py CSV  (rows: unix time, ICAO address, frame hex)
"""
import json
import sys

import pyModeS

FIELDS = {
    # pyModeS name -> the decode output's (readsb's) name
    "selected_altitude_mcp": "nav_altitude_mcp",
    "selected_altitude_fms": "nav_altitude_fms",
    "baro_pressure_setting": "nav_qnh",
    "roll": "roll",
    "true_track": "track",
    "groundspeed": "gs",
    "track_rate": "track_rate",
    "true_airspeed": "tas",
    "magnetic_heading": "mag_heading",
    "indicated_airspeed": "ias",
    "mach": "mach",
    "baro_vertical_rate": "baro_rate",
    "inertial_vertical_rate": "geom_rate",
    "callsign": "flight",
}

with open(sys.argv[1], encoding="utf-8-sig") as f:
    for line in f:
        if not line.strip():
            continue
        t, icao, frame = line.strip().split(",")
        d = pyModeS.decode(frame)
        out = {"t": int(t), "hex": icao, "frame": frame, "bds": d.get("bds")}
        if d.get("bds_candidates"):
            out["candidates"] = d["bds_candidates"]
        out["fields"] = {ours: d[theirs] for theirs, ours in FIELDS.items() if theirs in d}
        print(json.dumps(out))
