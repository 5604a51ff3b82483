"""``if_to_bag INPUT OUT --item-type T --sampling-frequency-hz F --start-time T``: raw front-end samples -> a bag.

Reads a capture file (or standard input, ``-``) with :mod:`rfi_experiments.if_formats`, the reader of the
``if_source`` node, and writes every whole block as ``rfi_msgs/IfSamples`` on ``/rfi/if_samples`` (log time =
header stamp), with :func:`rfi_experiments.if_source.block_message`, the node's own conversion: a bag made
here and the node's output hold the same messages. Nothing is lost: there is no pacing, every block is
written. The format options are the node's parameters (same names, ``-`` for ``_``, same documentation).

A file whose size is not a whole number of items is refused (usually a wrong ``--item-type``); a last block
shorter than the block duration is not written and is reported, as are trailing bytes of standard input and
inexact float conversions (gr_complex). Exit codes: 0 written, 2 refused input (one line on stderr).
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from collections.abc import Sequence
from pathlib import Path

from rfi_experiments import cli
from rfi_experiments.bag_io import BagError, BagWriter
from rfi_experiments.if_formats import (
    BlockAssembler,
    FormatError,
    IfFormat,
    check_file_size,
    iter_file_blocks,
    parse_start_time,
)
from rfi_experiments.if_source import FORMAT_FIELDS, IfSourceParams, block_message
from rfi_experiments.progress import ProgressLine

PROG = 'if_to_bag'
_fail = cli.error_reporter(PROG)
IF_TOPIC = '/rfi/if_samples'
READ_BYTES = 1 << 20


def _doc(name: str) -> tuple[object, str, tuple[str, ...]]:
    f = {f.name: f for f in dataclasses.fields(IfSourceParams)}[name]
    doc = f.metadata['rfi_doc']
    return f.default, doc['description'], tuple(doc['choices'])


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog=PROG,
        description='Convert a GNSS front-end capture (GNSS-SDR item types, PocketSDR int8, rtl_sdr uint8, '
                    'hackrf int8, packed 2-/4-bit) into a bag of rfi_msgs/IfSamples on ' + IF_TOPIC + ', one '
                    'message per block, stamped from --start-time (ROS time, UTC). Formats: '
                    'rfi_experiments/if_formats.py.')
    parser.add_argument('input', help='capture file, or - for standard input')
    parser.add_argument('out', help='bag directory to write')
    parser.add_argument('--overwrite', action='store_true', help='replace an existing bag')
    parser.add_argument('--start-time', required=True, metavar='T',
                        help='time of the first sample: ISO 8601 UTC (2021-12-02T08:47:00Z) or Unix seconds')
    for name in (*FORMAT_FIELDS, 'block_duration_s', 'frame_id'):
        default, text, choices = _doc(name)
        flag = '--' + name.replace('_', '-')
        if isinstance(default, bool):
            parser.add_argument(flag, type=_bool, nargs='?', const=True, default=default, metavar='true|false',
                                help=f'{text} (default {str(default).lower()}; the flag alone: true)')
        else:
            kind = type(default)
            parser.add_argument(flag, type=kind, default=default, choices=choices or None,
                                required=name in ('item_type', 'sampling_frequency_hz'),
                                help=text + ('' if name in ('item_type', 'sampling_frequency_hz')
                                             else f' (default {default!r})'))
    parser.add_argument('--max-duration-s', type=float, default=0.0, metavar='D',
                        help='stop after D seconds of samples (0: the whole input)')
    return parser


def _bool(text: str) -> bool:
    low = text.strip().lower()
    if low in ('true', '1', 'yes'):
        return True
    if low in ('false', '0', 'no'):
        return False
    raise argparse.ArgumentTypeError(f'expected true or false, got {text!r}')


def convert(input_path: str, out: str | Path, fmt: IfFormat, block_duration_s: float, start_ns: int, *,
            frame_id: str = 'gnss_front_end', overwrite: bool = False, max_duration_s: float = 0.0,
            stdin: object = None, progress: ProgressLine | None = None) -> BlockAssembler:
    """Write the blocks of ``input_path`` ('-': ``stdin``, a binary stream) to the bag ``out``.

    ``progress``, if given, gets its total (the blocks to write; unknown for ``stdin``) and one count per
    block, and is closed at the end.

    Returns:
        The assembler, whose ``counters`` say what was written and what was left over.

    Raises:
        FormatError: a format or a file that does not fit it; BagError: the bag cannot be written.
    """
    block_samples = fmt.block_samples(block_duration_s)
    max_blocks = int(max_duration_s * fmt.sampling_frequency_hz) // block_samples if max_duration_s > 0 else 0
    if max_duration_s > 0 and max_blocks < 1:
        raise FormatError(f'--max-duration-s {max_duration_s} is shorter than one block')
    asm = BlockAssembler(fmt, block_samples, start_ns)
    if input_path == '-':
        stream = stdin if stdin is not None else sys.stdin.buffer
        blocks = _stream_blocks(stream, asm)
    else:
        size = check_file_size(input_path, fmt, block_samples)  # before the bag exists: a refused input leaves nothing
        blocks = iter_file_blocks(input_path, fmt, block_samples, start_ns, asm, READ_BYTES)
        if progress is not None:
            in_file = size // fmt.chunk_bytes * fmt.chunk_samples // block_samples
            progress.total = min(in_file, max_blocks) if max_blocks else in_file
    try:
        with BagWriter(out, overwrite=overwrite) as bag:
            for n, block in enumerate(blocks, 1):
                bag.write(IF_TOPIC, block_message(block, fmt, frame_id), block.stamp_ns)
                if progress is not None:
                    progress.update(1)
                if max_blocks and n >= max_blocks:
                    break
    finally:
        if progress is not None:
            progress.close()
    return asm


def _stream_blocks(stream: object, asm: BlockAssembler):  # type: ignore[no-untyped-def]
    read = stream.read  # type: ignore[attr-defined]
    while data := read(READ_BYTES):
        yield from asm.feed(data)
    asm.finish()


def main(argv: Sequence[str] | None = None) -> int:
    """Console entry point (``argv`` a full argument vector, as ``sys.argv``). Returns 0, or 2 on bad input."""
    return cli.run_converter(build_parser(), argv, _fail, (FormatError, BagError, OSError), _convert, _summary)


def _convert(args: argparse.Namespace, out: Path) -> tuple[IfFormat, BlockAssembler]:
    fmt = IfFormat(**{name: getattr(args, name) for name in FORMAT_FIELDS})
    start_ns = parse_start_time(args.start_time)
    progress = ProgressLine(f'if_to_bag {Path(args.input).name}', unit='block', enabled=not args.quiet)
    return fmt, convert(args.input, out, fmt, args.block_duration_s, start_ns, frame_id=args.frame_id,
                        overwrite=args.overwrite, max_duration_s=args.max_duration_s, progress=progress)


def _summary(args: argparse.Namespace, result: tuple[IfFormat, BlockAssembler]) -> list[str]:
    fmt, asm = result
    c = asm.counters
    block_samples = fmt.block_samples(args.block_duration_s)
    lines = [f'  {IF_TOPIC}  {c["blocks"]} blocks of {block_samples} samples '
             f'({block_samples / fmt.sampling_frequency_hz:g} s), {c["samples"]} samples, {c["bytes_in"]} bytes read']
    for key, text in (('final_partial_block_samples', 'samples after the last whole block, not written'),
                      ('trailing_bytes', 'trailing bytes (the input ended inside an item), ignored'),
                      ('rounded_values', 'float values rounded to whole counts'),
                      ('clipped_values', 'float values clipped to +-32767 counts'),
                      ('non_finite_values', 'non-finite float values written as 0')):
        if c[key]:
            lines.append(f'  warning: {c[key]} {text}')
    return lines

if __name__ == '__main__':
    sys.exit(main())
