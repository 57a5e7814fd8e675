#!/usr/bin/env python3
"""One markdown table row from the JSON lines of repeated `stokesvdb analytic --json` runs of one
configuration (stdin): medians of the times, the other fields from the first run.

    summarise_solves.py LABEL COLUMN...

Columns: tiles, unknowns, status, iterations, L1, schur_block (as printed by stokesvdb);
solve (median solve seconds); setup_share (median multigrid set-up / median solve);
ns_per_unknown_it and ms_per_it ((solve - set-up) per iteration, per unknown or in ms);
ms_per_it_total (solve per iteration, set-up included); peak_rss_mb and bytes_per_unknown (the
process's peak resident memory, whole and per unknown); viscous_number (mu dt / (rho dx^2) with
dx = 1 / n, the analytic cases' convention).
"""
import json
import statistics
import sys


def main():
    label, columns = sys.argv[1], sys.argv[2:]
    rows = [json.loads(line) for line in sys.stdin if line.strip()]
    if not rows:
        sys.exit(f"summarise_solves.py: no runs for '{label}'")
    solve = statistics.median(r["solve_seconds"] for r in rows)
    setup = statistics.median(r["preconditioner_seconds"] for r in rows)
    r = rows[0]
    it = max(r["iterations"], 1)
    values = {
        "tiles": lambda: str(r["tiles"]),
        "unknowns": lambda: str(r["unknowns"]),
        "status": lambda: r["status"],
        "iterations": lambda: str(r["iterations"]),
        "L1": lambda: f"{r['L1']:.4g}",
        "schur_block": lambda: r["schur_block"],
        "solve": lambda: f"{solve:.3f}",
        "setup_share": lambda: f"{100 * setup / solve:.1f}%",
        "ns_per_unknown_it": lambda: f"{1e9 * (solve - setup) / it / max(r['unknowns'], 1):.0f}",
        "ms_per_it": lambda: f"{1e3 * (solve - setup) / it:.2f}",
        "ms_per_it_total": lambda: f"{1e3 * solve / it:.2f}",
        "peak_rss_mb": lambda: f"{r['peak_rss_mb']:.0f}",
        "bytes_per_unknown": lambda: f"{1048576 * r['peak_rss_mb'] / max(r['unknowns'], 1):.0f}",
        "viscous_number": lambda: f"{r['mu'] * r['dt'] / r['rho'] * r['n'] ** 2:.3g}",
    }
    unknown = [c for c in columns if c not in values]
    if unknown:
        sys.exit(f"summarise_solves.py: unknown column(s) {', '.join(unknown)} (known: {', '.join(values)})")
    print("| " + " | ".join([label] + [values[c]() for c in columns]) + " |")


if __name__ == "__main__":
    main()
