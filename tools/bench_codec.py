#!/usr/bin/env python3
"""Per-frame decode of :class:`suspid.can.codec.MessageCodec`: its generated decoder beside
the same decode written as a plain loop over the signals.

The plain loop is the code the generated one replaces (shifts and masks on
``int.from_bytes``, two's complement, scale and offset applied only when not 1 and 0); both
are checked equal on every frame before timing. Prints µs per frame of each, best of
``--repeat`` alternations, and the ratio plain / generated.

Usage: ``python tools/bench_codec.py [--repeat N] [--frames N]``
"""
from __future__ import annotations

import argparse
import timeit
from typing import Callable

from suspid.can.codec import MessageCodec
from suspid.can.dbc import load_dbc

#: the messages of suspid's DBC timed (a sync frame and two data frames)
MESSAGES = ("SN_Sync", "QC_Body", "QC_Wheel")


def plain_decode(codec: MessageCodec) -> Callable[[bytes], tuple]:
    """The scaled decode of ``codec``'s integer signals as a loop (no generated code)."""
    fields = []
    for s in codec.specs:
        sc = None if s.scale == 1.0 and s.offset == 0.0 else (s.scale, s.offset)
        fields.append((s.big_endian, s.start, (1 << s.length) - 1,
                       (1 << (s.length - 1)) if s.signed else 0, sc))
    fb = int.from_bytes

    def dec(data: bytes) -> tuple:
        vl = fb(data, "little")
        vb = fb(data, "big")
        out = []
        for big, start, mask, sign, sc in fields:
            r = ((vb if big else vl) >> start) & mask
            if sign:
                r -= (r & sign) << 1
            if sc is not None:
                r = r * sc[0] + sc[1] if sc[1] else r * sc[0]
            out.append(r)
        return tuple(out)
    return dec


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeat", type=int, default=3, help="alternations (best kept)")
    ap.add_argument("--frames", type=int, default=50000, help="decodes per timing")
    args = ap.parse_args()
    db = load_dbc(None)
    data = bytes(range(8))
    print(f"{'message':10s} {'generated µs':>13s} {'plain µs':>9s} {'plain/generated':>16s}")
    for name in MESSAGES:
        codec = MessageCodec(db.get_message_by_name(name))
        plain = plain_decode(codec)
        if plain(data) != codec.decode(data):
            raise SystemExit(f"{name}: the plain decode differs from the generated one")
        gen_t, plain_t = [], []
        for _ in range(args.repeat):
            gen_t.append(timeit.timeit(lambda f=codec.decode: f(data), number=args.frames))
            plain_t.append(timeit.timeit(lambda f=plain: f(data), number=args.frames))
        g, p = min(gen_t) / args.frames * 1e6, min(plain_t) / args.frames * 1e6
        print(f"{name:10s} {g:13.2f} {p:9.2f} {p / g:16.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
