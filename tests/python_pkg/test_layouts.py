"""Any conforming MCAP writer (issue 15, first part): the bundled recordings
rewritten by the `mcap` package's writer in other layouts (lz4, zstd and
uncompressed chunks, no chunks, tiny chunks, no statistics, summary offsets
or indexes, repeated or single schema and channel records) replay to the
same bits as the originals: measurements, field, per-train figures, summary
and end state."""

from __future__ import annotations

from pathlib import Path

import pytest
from mcap.reader import make_reader
from mcap.writer import CompressionType, IndexType, Writer

import tortwin
from conftest import RECORDINGS

LAYOUTS = {
    "zstd": dict(compression=CompressionType.ZSTD),
    "lz4": dict(compression=CompressionType.LZ4),
    "uncompressed chunks": dict(compression=CompressionType.NONE),
    "unchunked": dict(use_chunking=False),
    "tiny lz4 chunks": dict(compression=CompressionType.LZ4, chunk_size=512),
    "lz4, no repeated schemas or channels": dict(
        compression=CompressionType.LZ4, repeat_channels=False, repeat_schemas=False
    ),
    "no statistics, summary offsets or indexes": dict(
        index_types=IndexType.NONE, use_statistics=False, use_summary_offsets=False
    ),
    "unchunked, no summary data": dict(
        use_chunking=False, index_types=IndexType.NONE, use_statistics=False,
        use_summary_offsets=False, repeat_channels=False, repeat_schemas=False,
    ),
}


def rewrite(src: Path, dst: Path, reverse: bool = False, **options) -> None:
    """The recording's messages in their file order (or the /section
    message, then all the others in reverse), in another layout."""
    with open(src, "rb") as f_in, open(dst, "wb") as f_out:
        writer = Writer(f_out, **options)
        writer.start(profile="", library="tortwin tests (python mcap)")
        schemas: dict[int, int] = {}
        channels: dict[int, int] = {}
        records = list(make_reader(f_in).iter_messages(log_time_order=False))
        if reverse:
            records = records[:1] + records[:0:-1]
        for schema, channel, message in records:
            if schema is not None and schema.id not in schemas:
                schemas[schema.id] = writer.register_schema(schema.name, schema.encoding, schema.data)
            if channel.id not in channels:
                channels[channel.id] = writer.register_channel(
                    channel.topic, channel.message_encoding, schemas.get(channel.schema_id, 0)
                )
            writer.add_message(
                channels[channel.id], log_time=message.log_time,
                publish_time=message.publish_time, data=message.data, sequence=message.sequence,
            )
        writer.finish()


def outputs(path: Path):
    run = tortwin.replay(path, per_train=True)
    return run.measurements, run.field, run.per_train, run.summary, run.state.json


# curve_day_bands_rain has its tribometer readings at the end of the file,
# out of time order.
@pytest.mark.parametrize("recording", ["demo_day.mcap", "curve_day_bands_rain.mcap"])
@pytest.mark.parametrize("layout", list(LAYOUTS))
def test_every_layout_replays_to_the_same_bits(tmp_path, recording, layout):
    original = RECORDINGS / recording
    rewritten = tmp_path / "rewritten.mcap"
    rewrite(original, rewritten, **LAYOUTS[layout])
    assert rewritten.read_bytes() != original.read_bytes()
    expected = outputs(original)
    got = outputs(rewritten)
    names = ["measurements", "field", "per_train", "summary", "state"]
    for name, a, b in zip(names, expected, got):
        if hasattr(a, "equals"):
            assert a.equals(b), (layout, name)
        else:
            assert a == b, (layout, name)


@pytest.mark.parametrize(
    "layout",
    [
        dict(compression=CompressionType.LZ4, chunk_size=4096),
        # Unchunked and reversed: every message a run of its own, merged.
        dict(use_chunking=False),
    ],
    ids=["4 kB lz4 chunks", "unchunked"],
)
def test_messages_in_reverse_file_order_replay_to_the_same_bits(tmp_path, layout):
    """Every message but /section written in reverse (across 4 kB lz4
    chunks, or without chunks): the reader's replay order (log_time, topic)
    makes the same run; only the messages' indices in the file differ."""
    original = RECORDINGS / "curve_day_bands_rain.mcap"
    rewritten = tmp_path / "reversed.mcap"
    rewrite(original, rewritten, reverse=True, **layout)
    expected = outputs(original)
    got = outputs(rewritten)
    keys = ["time_utc", "site", "rail", "quantity", "train_id", "axle_index"]
    order = [(k, "ascending") for k in keys]
    a = expected[0].drop_columns(["index_in_file"]).sort_by(order)
    b = got[0].drop_columns(["index_in_file"]).sort_by(order)
    assert a.num_rows > 1000 and a.equals(b)
    assert expected[1].equals(got[1]) and expected[2].equals(got[2])
    assert expected[4] == got[4]
    # The summary's RMSE adds the squared residuals in the order the
    # measurements came, and measurements logged at one instant come in file
    # order: the sum may differ in its last bit.
    summary_a, summary_b = dict(expected[3]), dict(got[3])
    rmse_a, rmse_b = summary_a.pop("rmse"), summary_b.pop("rmse")
    assert summary_a == summary_b
    for q in rmse_a:
        assert rmse_a[q]["n"] == rmse_b[q]["n"]
        assert rmse_a[q]["rmse"] == pytest.approx(rmse_b[q]["rmse"], rel=1e-14)
