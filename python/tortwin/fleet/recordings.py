"""Recordings (MCAP, with the `mcap` package's reader and writer): a
section's consecutive days merged into one recording, the input of its
studies, and a recording of several days cut into one file per service
day."""

from __future__ import annotations

import os
import time
from pathlib import Path
from typing import Iterable

import tortwin


def merge_recordings(paths: Iterable[Path], out: Path) -> None:
    """One recording of several consecutive days of one section: the first
    day's /section message, then every other message of every day in order
    (with the `mcap` package's reader and writer)."""
    from mcap.reader import make_reader
    from mcap.writer import Writer

    with open(out, "wb") as f_out:
        writer = Writer(f_out)
        writer.start(profile="", library=f"tortwin-fleet {tortwin.__version__}")
        # A channel without a schema has the key None, never in schemas.
        schemas: dict[tuple[str, str, bytes] | None, int] = {}
        channels: dict[tuple, int] = {}
        section_written = False
        for path in paths:
            with open(path, "rb") as f_in:
                for schema, channel, message in make_reader(f_in).iter_messages(log_time_order=True):
                    if channel.topic == "/section":
                        if section_written:
                            continue
                        section_written = True
                    skey = (schema.name, schema.encoding, schema.data) if schema else None
                    if skey is not None and skey not in schemas:
                        schemas[skey] = writer.register_schema(*skey)
                    ckey = (channel.topic, channel.message_encoding, skey)
                    if ckey not in channels:
                        channels[ckey] = writer.register_channel(
                            channel.topic, channel.message_encoding, schemas.get(skey, 0)
                        )
                    writer.add_message(
                        channels[ckey],
                        log_time=message.log_time,
                        publish_time=message.publish_time,
                        data=message.data,
                    )
        writer.finish()


def split_by_day(recording: str | os.PathLike, folder: str | os.PathLike) -> dict[str, Path]:
    """Cuts a recording of several days into one recording per service day,
    ``folder/YYYY-MM-DD.mcap``: a day holds the messages from its first
    train's passage (UTC date) to the next day's first train, so that no
    train is in the section at a cut; each file opens with the /section
    message (logged at the day's first message). Returns the files by date."""
    from mcap.reader import make_reader
    from mcap.writer import Writer

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    with open(recording, "rb") as f:
        messages = [(s, c, m) for s, c, m in make_reader(f).iter_messages(log_time_order=True)]
    section = [x for x in messages if x[1].topic == "/section"]
    if not section:
        raise ValueError(f"{recording}: no /section message")
    first_of_day: dict[str, int] = {}
    for _, channel, message in messages:
        if channel.topic == "/train/passage":
            date = time.strftime("%Y-%m-%d", time.gmtime(message.log_time // 1_000_000_000))
            first_of_day.setdefault(date, message.log_time)
    if not first_of_day:
        raise ValueError(f"{recording}: no /train/passage message")
    starts = sorted(first_of_day.items(), key=lambda kv: kv[1])
    out: dict[str, Path] = {}
    for k, (date, start) in enumerate(starts):
        end = starts[k + 1][1] if k + 1 < len(starts) else None
        lo = None if k == 0 else start
        day = [
            x for x in messages
            if x[1].topic != "/section"
            and (lo is None or x[2].log_time >= lo)
            and (end is None or x[2].log_time < end)
        ]
        path = folder / f"{date}.mcap"
        with open(path, "wb") as f_out:
            writer = Writer(f_out)
            writer.start(profile="", library=f"tortwin-fleet {tortwin.__version__}")
            schemas: dict[int, int] = {}
            channels: dict[int, int] = {}
            opening = section[0][2].log_time if k == 0 else min(start, day[0][2].log_time)
            for schema, channel, message in [section[0], *day]:
                if schema is not None and schema.id not in schemas:
                    schemas[schema.id] = writer.register_schema(schema.name, schema.encoding, schema.data)
                if channel.id not in channels:
                    channels[channel.id] = writer.register_channel(
                        channel.topic, channel.message_encoding, schemas.get(channel.schema_id, 0)
                    )
                t = opening if channel.topic == "/section" else message.log_time
                writer.add_message(channels[channel.id], log_time=t, publish_time=t, data=message.data)
            writer.finish()
        out[date] = path
    return out
