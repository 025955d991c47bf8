"""The only place the paper audit touches the file system: ``write_audit`` claims and locks
the output directory through the command line's one writer (``cli._io.Outputs``: resolved
paths, ``--force`` checked before any work, atomic writes), then writes the files of each
step of ``_audit.audit_steps`` as soon as it is measured: an audit stopped at any moment
(SIGINT, SIGTERM, a crash) leaves every finished claim on disk, the rest marked ``not run``,
and ``resume`` runs only those.
"""

import json
import os
import sys

from ..core._errors import InputError

MARKER = "claims.json"  # every record, finished or "not run": rewritten after each claim, last


def finished_records(out, what: str) -> tuple[list[str], list[dict]]:
    """(the claim ids of the audit in ``out``, its finished records that ``resume`` keeps: each
    with its figure, if it draws one); an error when ``out`` holds no audit."""
    from ._audit import CLAIM_IDS
    from ._figures import figure_name
    from ._records import NOT_RUN

    path = out / MARKER
    if not path.exists():
        raise InputError(f"nothing to resume: {what} holds no {MARKER}; run the audit without --resume")
    try:
        records = json.loads(path.read_text(encoding="utf-8"))
        ids = [r["id"] for r in records]
        kept = [r for r in records if r["verdict"] != NOT_RUN]
    except (OSError, ValueError, TypeError, KeyError) as err:
        raise InputError(f"cannot resume: {str(path)!r} is not a jaxsplit audit ({err})") from None
    unknown = [cid for cid in ids if cid not in CLAIM_IDS]
    if unknown or not ids:
        raise InputError(f"cannot resume: {str(path)!r} names unknown claim ids {unknown}" if unknown else
                         f"cannot resume: {str(path)!r} holds no claim")
    # a finished claim whose figure is missing is measured again
    kept = [r for r in kept if figure_name(r["id"]) is None or (out / figure_name(r["id"])).exists()]
    return ids, kept


def write_audit(out_dir, claims=None, *, figures: bool = True, force: bool = False, resume: bool = False,
                on_done=None) -> list[dict]:
    """Audit into ``out_dir`` claim by claim (see the module docstring); return the records.
    ``on_done(records, out)`` runs with the last files, while signals are only recorded."""
    from ..cli import _io, _signals
    from ._audit import audit_steps, output_names, require_x64
    from ._records import NOT_RUN

    require_x64()  # before the directory is touched
    if resume and force:
        raise InputError("--resume and --force contradict each other (continue the audit, or start it over)")
    if resume and claims is not None:
        raise InputError("--claims has no effect with --resume: the audit resumes the claims it was started with")
    with _io.Outputs(force=force or resume) as outputs:
        out = outputs.directory(out_dir, "--out directory", resume=resume)  # locked: a second audit into it exits 2
        shown = repr(os.fspath(out_dir))
        finished = ()
        if resume:
            claims, finished = finished_records(out, f"--out {shown}")
        elif (out / MARKER).exists() and not force:
            raise InputError(f"--out {shown} already holds an audit; pass --resume to finish it or --force to "
                             "start it over")
        for name in output_names(claims, figures=figures):  # claimed up front: --force checked before any work
            outputs.file(out / name, "audit")
        outputs.remove_temporaries(out)  # of a killed run (we hold the lock)
        stop, records = _signals.current(), []

        def saved():  # the process is abandoned inside a claim: say what is kept
            os.write(2, f"jaxsplit: {_saved(records, out)}\n".encode())

        with stop.cleanup(saved):
            for files in audit_steps(claims, figures=figures, finished=finished):  # a signal inside a claim
                with stop.critical():  # abandons at once; while these files are written it waits for them
                    for name, data in files.items():  # claims.json last
                        outputs.write_bytes(out / name, data)
                    records[:] = json.loads(files[MARKER])
                if stop.requested and any(r["verdict"] == NOT_RUN for r in records):
                    print(f"jaxsplit: interrupted ({stop.signal_name}): {_saved(records, out)}", file=sys.stderr)
                    raise _signals.Interrupted(stop.received, "")
        if on_done is not None:
            with stop.critical():
                on_done(records, out)
        return records


def _saved(records, out) -> str:
    from ._records import NOT_RUN

    left = sum(r["verdict"] == NOT_RUN for r in records)
    return (f"{len(records) - left} of {len(records)} claims are saved in {out} (report.md marks the other {left} "
            f"'not run'); continue with: jaxsplit paper --out {out} --resume")
