"""``attitude-bench inspect FILE``: what a logged file holds — each sensor's
rate, jitter and gaps, clipping, rest, gravity, the field — and, for a file
with no declaration yet, the ``[recording]`` file its columns suggest
(written beside it, or into ``--out``, for the user to check and edit)."""
from __future__ import annotations

import os
import shlex
import sys
from pathlib import Path

from benchmarks.commands.options import PROG, UsageError, add_divergence_option

OUTPUTS = ()
memory = None


def arguments(commands, defaults) -> None:
    """The ``inspect`` command's arguments."""
    inspect = commands.add_parser(
        "inspect", help="what a logged file holds (rates, jitter, gaps, clipping, rest, "
        "gravity, the field) and the [recording] declaration it suggests; writes FILE.toml")
    inspect.add_argument("file", type=Path, metavar="FILE",
                         help="the log (.csv, .parquet, .npz, .mat, .h5, .hdf5), or a "
                         "[recording] .toml declaring one")
    inspect.add_argument("--out", type=Path, default=None, metavar="DIR",
                         help="where the suggested declaration goes (default: beside FILE)")
    inspect.add_argument("--quiet", action="store_true", help="accepted, as by every command")
    add_divergence_option(inspect)


def _check_beside(target: Path) -> None:
    """Refuse, before any work, a file's folder that cannot take the
    declaration suggested beside it (``target``)."""
    from benchmarks.output import check_output_folder
    from dynamics.validation import InvalidParameterError
    try:
        check_output_folder(target.parent, (target.name,))
    except InvalidParameterError as err:
        raise UsageError(f"{err}: inspect writes its suggested declaration beside the file; "
                         "give --out DIR") from None


def run(args, _scenario):
    from sensors.declared import (SENSORS, data_file, declared_recordings, read_declaration,
                                  sensor_tables)
    from sensors.tables import read_table
    from benchmarks.experiments.inspection import (declaration_toml, findings,
                                                   guess_declaration, loaded_guess, next_step)
    if not args.file.is_file():
        raise UsageError(f"file = {str(args.file)!r}: is not a file")
    declared = args.file.suffix.lower() == ".toml"
    target = None
    if declared:
        declaration = read_declaration(args.file)
        data = data_file(args.file, declaration) if "file" in declaration else None
        table, notes = (read_table(data) if data else {}), []
    else:
        target = (args.out or args.file.parent) / f"{args.file.stem}.toml"
        if args.out is None:          # a given --out was checked before any work (cli)
            _check_beside(target)
        if target.exists():
            raise UsageError(f"out = {str(target.parent)!r}: already holds {target.name}; "
                             "inspect does not overwrite it: remove it or give --out DIR")
        data, table = args.file, read_table(args.file)
        relative = os.path.relpath(args.file.resolve(), target.parent.resolve())
        declaration, notes = guess_declaration(table, relative)
    tables = sensor_tables(args.file, declaration, table) if declared else \
        dict.fromkeys(SENSORS, table)
    files = {data.name: table} if data else {}
    files.update((Path(declaration[sensor]["file"]).name, tables[sensor]) for sensor in SENSORS
                 if isinstance(declaration.get(sensor), dict) and "file" in declaration[sensor])
    for name, columns in files.items():
        print(f"{name}: {len(columns)} columns ({', '.join(list(columns)[:12])}"
              f"{', …' if len(columns) > 12 else ''})")
    # The user's own declaration: its error, exit 2; a guess: a note.
    parts = declared_recordings(declaration, tables, args.file) if declared else \
        loaded_guess(declaration, table, target, notes)
    if parts is not None:
        for line in findings(parts, tables, declaration):
            print(f"  {line}")
    for note in notes:
        print(f"{PROG}: note: {note}", file=sys.stderr)
    if target is not None:
        from benchmarks.output import write_text
        write_text(target, declaration_toml(declaration, args.file.name, parts is not None))
        if parts is None:     # a skeleton to complete: said, and not a success
            raise UsageError(f"wrote {target}, which does not load as suggested (the note "
                             "above): complete it by hand, "
                             + next_step(declaration, shlex.quote(str(target))))
        print(f"wrote {target}: check it, {next_step(declaration, shlex.quote(str(target)))}")
    return None
