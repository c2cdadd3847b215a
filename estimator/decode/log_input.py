"""A CAN log as a :class:`suspid.io.csvio.Measurement` (``suspid identify --input LOG``): decoded,
aligned on a uniform grid; gaps in a road channel bridged linearly, with a warning."""
from __future__ import annotations

from pathlib import Path
from typing import Iterable, Literal, cast

import numpy as np
from cantools.database import Database

from estimator.decode.buffer import Aligned, cadence, collision_notes
from estimator.decode.listener import DecodeListener
from estimator.decode.replay import feed_log
from suspid.can.logs import ReadStats, describe_channels
from suspid.can.signal_map import SignalMapLike
from suspid.errors import InputError
from suspid.io.csvio import AUX_CHANNELS, Measurement
from suspid.models import SuspensionModel, get_model


def unparsed_hint(path: str | Path, stats: ReadStats) -> str:
    """``"; nothing parsed, ..."`` when a log reader parsed no frame but skipped lines, else ``""``."""
    if stats.damage and not stats.frames:
        return f"; {stats.damage}"
    if stats.frames or not stats.examples:
        return ""
    first = stats.examples[0]
    first = first[len(str(path)) + 1:] if first.startswith(f"{path}:") else first
    out = f"; nothing parsed, the first skipped: line {first}"
    if str(path).lower().endswith(".log"):
        out += " (a .log is read as candump -L: '(SECONDS) IFACE ID#DATA' per line)"
    return out


def channel_notes(path: str | Path, stats: ReadStats, keys: Iterable[int],
                  channel: str | None) -> tuple[dict[str, object], list[str]]:
    """Frame statistics and warnings about the bus channels of a log read with ``stats``."""
    extra: dict[str, object] = {}
    if len(stats.channels) > 1 or channel is not None:
        extra["channels"] = stats.channel_frames()
    if channel is not None:
        extra["channel"] = channel
        extra["other_channel"] = stats.other_channel
        return extra, []
    carrying = {ch: n for ch, n in stats.channel_frames(keys).items() if n}
    if len(carrying) < 2:
        return extra, []
    return extra, [f"{path}: the sensor's messages are on {len(carrying)} bus channels, "
                   f"{describe_channels(carrying)}, and were decoded together; choose one "
                   "with the --config file's can.channel"]


def summarize_gaps(aligned: Aligned) -> list[str]:
    """One warning line per channel with missing samples."""
    out = []
    by_ch: dict[str, list] = {}
    for g in aligned.gaps:
        by_ch.setdefault(g.channel, []).append(g)
    for ch, gaps in by_ch.items():
        n = sum(g.samples for g in gaps)
        if n >= aligned.t.size:
            continue  # never sent (absent column): not a gap
        every = cadence(aligned.values[ch])
        longest = max(gaps, key=lambda g: g.samples)
        out.append(f"channel {ch}: {n} of {aligned.t.size} samples missing in {len(gaps)} gap(s); "
                   f"longest {longest.samples} samples from t={longest.t_start:.6g} s"
                   + (f" (a sample every {every} grid cells)" if every > 1 else ""))
    return out


def aligned_to_measurement(aligned: Aligned, model: SuspensionModel, source: str = "",
                           warnings: list[str] | None = None) -> Measurement:
    """Split aligned channels into road inputs (gaps bridged linearly, with a warning), measured channels (NaN
    kept) and ``aux``."""
    warns = list(warnings or [])
    road_names = set(model.roads) | {f"{r}_dot" for r in model.roads}
    road: dict[str, np.ndarray] = {}
    measured: dict[str, np.ndarray] = {}
    aux: dict[str, np.ndarray] = {}
    t = aligned.t
    for ch, v in aligned.values.items():
        ok = ~np.isnan(v)
        if not ok.any():
            continue  # never sent (Valid = 0 throughout), like an absent CSV column
        if ch in AUX_CHANNELS:
            aux[ch] = v
        elif ch in road_names:
            if not ok.all():
                if ok.sum() < 2:
                    warns.append(f"{source}: road channel {ch!r} has fewer than 2 samples; not used")
                    continue
                v = np.interp(t, t[ok], v[ok])
                warns.append(f"{source}: road channel {ch!r}: {int((~ok).sum())} missing samples "
                             "bridged by linear interpolation")
            road[ch] = v
        else:
            measured[ch] = v
    for r in model.roads:
        if f"{r}_dot" in road and r not in road:
            road.pop(f"{r}_dot")
            warns.append(f"{source}: road velocity {r}_dot without {r}; not used")
    return Measurement(t=t, road=road, measured=measured, warnings=warns, source=source,
                       aux=aux)


def load_log_as_measurement(path: str | Path, model: str | SuspensionModel,
                            dbc_path: str | Path | Database | None = None,
                            signal_map: SignalMapLike = None, *,
                            time_source: Literal["timestamp", "tick", "auto"] = "auto",
                            dt: float | None = None,
                            max_counter_delta: int = 4,
                            arrival_slots: bool = True,
                            channel: str | None = None,
                            j1939_source: str | int | None = None,
                            ) -> tuple[Measurement, dict[str, object]]:
    """Decode a CAN log (``.log`` candump -L, ``.asc``, ``.blf``, ``.trc``, ``.mf4``) into a
    measurement on a uniform grid of step ``dt`` (s; default the median frame interval) and
    its frame statistics (:meth:`DecodeListener.frame_stats` plus :func:`channel_notes`).
    ``dbc_path``: a DBC or Database (default the signal map's ``dbc``, else suspid's);
    ``channel``: one bus channel of a multi-bus log (:func:`suspid.can.logs.channel_wanted`);
    the other options as :class:`~estimator.decode.listener.DecodeListener`'s.
    """
    m = get_model(model) if isinstance(model, str) else model
    listener = DecodeListener(m, dbc_path, signal_map, capacity=1 << 14, growable=True,
                              time_source=time_source, max_counter_delta=max_counter_delta,
                              arrival_slots=arrival_slots, j1939_source=j1939_source)
    stats = ReadStats()
    feed_log(listener, path, stats, channel=channel)
    listener.count_malformed(stats.malformed)
    frame_stats = listener.frame_stats()
    bus_stats, warnings = channel_notes(path, stats, listener.data_keys(), channel)
    frame_stats.update(bus_stats)
    warnings += listener.signal_map.unit_warnings(listener.db, m)
    mapped = {r.name for r in listener.routes.ordered}
    if listener.j1939 is not None:
        warnings += listener.j1939.warnings(str(path), mapped)
    warnings += [f"{e} (skipped)" for e in stats.examples]   # e names file and line
    if stats.malformed > len(stats.examples):
        warnings.append(f"{path}: {stats.malformed} unparseable lines/records skipped in all")
    if stats.damage:
        warnings.append(stats.damage)
    elif stats.truncated:
        warnings.append(f"{path}: the file ends inside a record (truncated); frames before it used")
    for name, n in listener.unknown_pages().items():
        warnings.append(f"{path}: {n} frames of {name} carry a multiplexer value that is no "
                        "page of the DBC (not decoded)")
    if listener.time_resyncs:
        warnings.append(f"{path}: timestamps jumped back {listener.time_resyncs} time(s); "
                        "the time base was re-anchored")
    retimed = {k: v for k, v in listener.arrival_stats.items() if v["retimed"]}
    if retimed:
        warnings.append(f"{path}: no sensor clock: frames of {', '.join(retimed)} placed in "
                        "their sample slots from their arrival times (period "
                        + ", ".join(f"{float(cast(float, v['period'])):.6g} s" for v in retimed.values())
                        + f"; {sum(int(cast(int, v['missing'])) for v in retimed.values())} "
                        "frames missing)")
    if not any(s.n for s in listener.buffer.sources.values()):
        rejected = cast("dict[str, int]", frame_stats["rejected"])   # reason -> count
        rej = {k: v for k, v in rejected.items() if v}
        unread = unparsed_hint(path, stats)
        if listener.j1939 is not None:
            unread += listener.j1939.hint(mapped)
        raise InputError(f"{path}: no accepted frame carries a channel of model {m.name} "
                         f"({stats.frames} frames read, {frame_stats['accepted']} accepted, "
                         f"rejected {rej or 'none'}; map: "
                         f"{', '.join(str(x) for x in listener.signal_map.mappings)}){unread}")
    aligned = listener.aligned(dt=dt)
    if aligned.snapped > 1e-3 * aligned.dt:
        warnings.append(f"{path}: frame times snapped to a uniform grid of {aligned.dt:.6g} s "
                        f"(largest shift {aligned.snapped:.3g} s)")
    warnings += collision_notes({k: v.size for k, v in aligned.collided.items()}, path,
                                frame_stats)
    warnings += [f"{path}: {w}" for w in summarize_gaps(aligned)]
    meas = aligned_to_measurement(aligned, m, str(path), warnings)
    if not meas.measured:
        raise InputError(f"{path}: no measured channel of model {m.name} in the log "
                         f"(decoded: {', '.join(aligned.values) or 'none'}); expected any of "
                         f"{', '.join(m.channels + m.ride_height_channels)}")
    return meas, frame_stats
