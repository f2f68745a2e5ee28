#!/usr/bin/env python3
"""Read `tortwin export`'s tables the way an engineer would (pyarrow and
pandas) and compare them with the MCAP output of the same replay.

Usage:
    check_tables.py TABLES_DIR OUT.mcap

Checks, independently of tortwin's Rust code:
- measurements.parquet and measurements.csv have the documented columns,
  one row per /twin/measurement message, in the same order, with `measured`
  and `simulated` equal to the message's (bit for bit in Parquet, to the
  round trip of the shortest decimal in CSV) and `residual` = measured -
  simulated; times are UTC timestamps equal to the message's log_time;
- field.parquet has one row per grid point of every /twin/field message,
  with d_m the grid of /twin/section, and mu, adhesion and the masses the
  message's at the precision the MCAP output writes them (docs/spec/
  interfaces.md: mu and adhesion to 1e-4, masses to 3 significant digits,
  below 1e-4 mg as 0); the tables keep the engine's full values;
- trains.parquet has one row per /twin/field message, with mu_min,
  mu_mean, mu_max of that message's mu (to its 1e-4).

Prints a JSON summary; exits 0 when all holds, 1 otherwise, 3 when a
package is missing (pip install pyarrow pandas mcap).
"""

import json
import math
import sys

try:
    import pandas as pd
    import pyarrow.parquet as pq
    from mcap.reader import make_reader
except ImportError as err:  # pragma: no cover
    print(f"check_tables.py: missing Python package ({err})", file=sys.stderr)
    sys.exit(3)

MEASUREMENT_COLUMNS = ["time_utc", "index_in_file", "site", "rail", "quantity", "train_id",
                       "axle_index", "measured", "simulated", "residual"]
FIELD_COLUMNS = ["train_id", "time_utc", "rail", "band", "wheel_pass", "d_m", "mu", "adhesion",
                 "rail_mass_mg", "wheel_mass_mg"]
TRAIN_COLUMNS = ["train_id", "time_utc", "end_utc", "direction", "speed_mps", "axles", "rail",
                 "band", "wheel_pass", "mu_min", "mu_mean", "mu_max", "share_in_band",
                 "share_below_band", "rail_product_g", "wheel_mass_out_mg"]


def main():
    tables, out_mcap = sys.argv[1], sys.argv[2]
    failures = []

    def check(ok, what):
        if not ok and len(failures) < 20:
            failures.append(what)

    measurements, fields, grid = [], [], None
    with open(out_mcap, "rb") as f:
        for _, channel, message in make_reader(f).iter_messages(
                topics=["/twin/section", "/twin/measurement", "/twin/field"]):
            body = json.loads(message.data)
            if channel.topic == "/twin/section":
                grid = body["grid_d_m"]
            elif channel.topic == "/twin/measurement":
                measurements.append((message.log_time, body))
            else:
                fields.append((message.log_time, body))
    check(grid is not None, "no /twin/section")
    grid = grid or []

    def mcap_precision(col, table, mcap):
        """Whether the table's full value rounds to the MCAP's."""
        if col in ("mu", "adhesion"):
            return abs(table - mcap) <= 0.5e-4 + 1e-12
        if mcap == 0.0:
            return abs(table) < 1e-4 * (1 + 1e-9)
        return abs(table - mcap) <= 0.5e-2 * abs(mcap) * (1 + 1e-9)

    m = pq.read_table(f"{tables}/measurements.parquet")
    check(m.column_names == MEASUREMENT_COLUMNS, f"measurement columns {m.column_names}")
    check(str(m.schema.field("time_utc").type) == "timestamp[ns, tz=UTC]",
          f"time_utc is {m.schema.field('time_utc').type}")
    df = m.to_pandas()
    check(len(df) == len(measurements), f"{len(df)} measurement rows, {len(measurements)} messages")
    for (log_time, body), row in zip(measurements, df.itertuples(index=False)):
        check(row.time_utc.value == log_time, f"time {row.time_utc} vs {log_time}")
        check(row.site == body["site_id"] and row.rail == body["rail"]
              and row.quantity == body["quantity"], f"names {row} vs {body}")
        check(row.measured == body["measured"] and row.simulated == body["simulated"],
              f"values {row.measured}, {row.simulated} vs {body}")
        check(row.residual == row.measured - row.simulated, f"residual {row}")
        if "train_id" in body:
            check(row.train_id == body["train_id"] and row.axle_index == body["axle_index"],
                  f"axle {row} vs {body}")
        else:
            check(pd.isna(row.train_id) and pd.isna(row.axle_index), f"rail_mu row {row}")

    csv = pd.read_csv(f"{tables}/measurements.csv")
    check(list(csv.columns) == MEASUREMENT_COLUMNS, f"csv columns {list(csv.columns)}")
    check(len(csv) == len(df), f"{len(csv)} csv rows vs {len(df)}")
    times = pd.to_datetime(csv["time_utc"], utc=True, format="ISO8601")
    check(bool((times.astype("int64").to_numpy() == df["time_utc"].astype("int64").to_numpy()).all()),
          "csv times differ from parquet")
    for col in ["measured", "simulated"]:
        check(bool((csv[col].to_numpy() == df[col].to_numpy()).all()), f"csv {col} differs")

    field = pq.read_table(f"{tables}/field.parquet")
    check(field.column_names == FIELD_COLUMNS, f"field columns {field.column_names}")
    fdf = field.to_pandas()
    points = sum(len(b["mu"]) for _, b in fields)
    check(len(fdf) == points, f"{len(fdf)} field rows, {points} grid points in /twin/field")
    at = 0
    for log_time, body in fields:
        n = len(body["mu"])
        check(n == len(grid), f"field of {body['train_id']}: {n} values, {len(grid)} grid points")
        part = fdf.iloc[at:at + n]
        at += n
        check((part["train_id"] == body["train_id"]).all() and (part["rail"] == body["rail"]).all()
              and (part["band"] == body["band"]).all(), f"field names at {body['train_id']}")
        check(int(part["time_utc"].iloc[0].value) == log_time, f"field time {body['train_id']}")
        check(int(part["wheel_pass"].iloc[0]) == body["wheel_pass"], "wheel_pass")
        check(part["d_m"].tolist() == grid, f"field d_m of {body['train_id']} is not grid_d_m")
        for col in ["mu", "adhesion", "rail_mass_mg", "wheel_mass_mg"]:
            want, got = body[col], part[col].tolist()
            check(all(mcap_precision(col, a, b) for a, b in zip(got, want)),
                  f"field {col} of {body['train_id']} {body['rail']}")

    trains = pq.read_table(f"{tables}/trains.parquet")
    check(trains.column_names == TRAIN_COLUMNS, f"train columns {trains.column_names}")
    tdf = trains.to_pandas()
    check(len(tdf) == len(fields), f"{len(tdf)} train rows, {len(fields)} field messages")
    for (_, body), row in zip(fields, tdf.itertuples(index=False)):
        mu = body["mu"]
        check(row.train_id == body["train_id"] and row.rail == body["rail"], f"train row {row}")
        close = lambda a, b: abs(a - b) <= 0.5e-4 + 1e-12  # noqa: E731
        check(close(row.mu_min, min(mu)) and close(row.mu_max, max(mu))
              and close(row.mu_mean, sum(mu) / len(mu)),
              f"mu statistics of {row.train_id}")
        check(0.0 <= row.share_in_band <= 1.0 and 0.0 <= row.share_below_band <= 1.0, "shares")

    print(json.dumps({"measurements": len(df), "field_rows": len(fdf), "train_rows": len(tdf),
                      "failures": failures}))
    sys.exit(1 if failures else 0)


if __name__ == "__main__":
    main()
