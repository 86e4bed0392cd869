"""``lowerbase campaign``: run a campaign of scenario runs on Dask, check one, replay one run
(docs/campaigns.md)."""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

from lowerbase.cli.args import positive_int


def add_subparser(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "campaign", help="run a scenario many times with varied parameters (Dask)",
        description="A campaign runs base scenarios many times with varied profile "
        "parameters, faults, initial states and seeds, on a Dask LocalCluster or an "
        "existing Dask cluster, and scores their expectations. See docs/campaigns.md.")
    sub = p.add_subparsers(title="actions", dest="campaign_command", metavar="ACTION")
    p.set_defaults(func=lambda args: (p.print_help(), 2)[1])

    run = sub.add_parser(
        "run", help="run every run of a campaign; write results.csv and the report",
        description="Run a campaign file's runs on Dask (a LocalCluster of one process per "
        "core on 127.0.0.1 unless --scheduler) and write results.csv, runs.jsonl, "
        "summary.json, index.html and plots. Ctrl-C keeps the runs that finished.")
    run.add_argument("campaign", metavar="CAMPAIGN.toml")
    run.add_argument("--out", metavar="DIR",
                     help="report directory (default: reports/campaign-NAME-TIMESTAMP)")
    where = run.add_mutually_exclusive_group()
    where.add_argument("--scheduler", metavar="tcp://HOST:8786",
                       help="an existing Dask scheduler (workers started with `dask worker` "
                       "where lowerbase is installed)")
    where.add_argument("--workers", type=positive_int, metavar="N",
                       help="LocalCluster worker processes (default: one per core)")
    run.add_argument("--runs", metavar="A-B",
                     help="only runs A..B (inclusive), e.g. 0-9, to try a campaign out")
    run.add_argument("--progress", action="store_true",
                     help="show the progress bar even when stderr is not a terminal")
    run.add_argument("--strict", action="store_true",
                     help="exit 1 when a run failed (default: 0 once every run finished; "
                     "failing runs are the campaign's findings)")
    run.set_defaults(func=run_command)

    check = sub.add_parser("check", help="validate a campaign file without running it")
    check.add_argument("campaign", metavar="CAMPAIGN.toml")
    check.set_defaults(func=check_command)

    replay = sub.add_parser(
        "replay", help="rerun one run of a campaign with its full report and MCAP",
        description="Rebuild run N from the campaign file alone and run it as "
        "`lowerbase scenario run` would: the scenario's report, run.mcap, and run.json "
        "(the run's values and seeds), scenario.toml and profile.toml.")
    replay.add_argument("campaign", metavar="CAMPAIGN.toml")
    replay.add_argument("--run", type=int, required=True, metavar="N")
    replay.add_argument("--out", metavar="DIR",
                        help="report directory (default: reports/NAME-runN-TIMESTAMP)")
    replay.add_argument("--no-mcap", dest="mcap", action="store_false",
                        help="do not write the MCAP recording")
    replay.add_argument("--progress", action="store_true",
                        help="show the progress bar even when stderr is not a terminal")
    replay.set_defaults(func=replay_command, mcap=None)


def _range(text: str | None, total: int) -> list[int] | None:
    from lowerbase.errors import CampaignError

    if text is None:
        return None
    try:
        a, _, b = text.partition("-")
        lo, hi = int(a), int(b or a)
    except ValueError:
        raise CampaignError(f"--runs {text}: give A-B, e.g. 0-9") from None
    if lo > hi:
        raise CampaignError(f"--runs {text}: A-B with A <= B, e.g. {hi}-{lo}")
    if not 0 <= lo <= hi < total:
        raise CampaignError(f"--runs {text}: this campaign has runs 0..{total - 1}")
    return list(range(lo, hi + 1))


def run_command(args: argparse.Namespace) -> int:
    from lowerbase.campaign import engine
    from lowerbase.campaign.plan import load_campaign
    from lowerbase.campaign.progress import CampaignProgress
    from lowerbase.campaign.report import write_report
    from lowerbase.campaign.table import RowLog, write_csv
    from lowerbase.cli.args import check_outputs

    campaign = load_campaign(args.campaign)
    indices = _range(args.runs, campaign.total)
    out = Path(args.out) if args.out else \
        Path("reports") / f"campaign-{campaign.name}-{time.strftime('%Y%m%d-%H%M%S')}"
    check_outputs(args, out)
    if args.scheduler is None:  # its workers' warm-up begins now, beside Dask's import here
        engine.start_forkserver()
    n = campaign.total if indices is None else len(indices)
    where = args.scheduler or f"a LocalCluster of {args.workers or 'one process per core'}"
    print(f"campaign {campaign.name}: {n} run(s) of {len(campaign.scenarios)} scenario(s) "
          f"on {where}", file=sys.stderr)
    t0 = time.monotonic()
    specs: dict[int, Any] = {}  # planned while the cluster starts and its workers warm
    result: engine.Outcome | None = None
    try:
        with engine.quiet_dask(args.debug), engine.open_client(
                args.scheduler, args.workers, warm=True,
                meanwhile=lambda: specs.update(engine.plan_runs(campaign, indices))) as client:
            log = RowLog(out / "runs.jsonl")  # once there is a cluster to run on
            try:
                result = engine.run_campaign(campaign, client, on_row=log, warm=False,
                                             specs=specs,
                                             progress=CampaignProgress(n, force=args.progress))
            finally:
                log.close()
    except KeyboardInterrupt:  # in the cluster's start, or its stop after the runs
        if result is None:
            print(f"campaign {campaign.name}: interrupted before a run started; nothing "
                  "written", file=sys.stderr)
            return 130
        result.interrupted = True
    rows = list(result.rows.values())
    write_csv(out / "results.csv", campaign, rows)
    summary = write_report(campaign, rows, out, campaign_arg=args.campaign,
                           interrupted=result.interrupted,
                           extra={"workers": result.workers,
                                  "wall_time_s": round(time.monotonic() - t0, 3)})
    for e in summary["expectations"]:
        rate = 100 * e["passed"] / e["scored"] if e["scored"] else 0.0
        print(f"  {rate:5.1f} %  {e['name']} ({e['passed']}/{e['scored']})")
    print(f"campaign {campaign.name}: {summary['passed']} passed, {summary['failed']} failed"
          f" of {summary['finished']} finished ({n} asked)"
          f"{', INTERRUPTED' if result.interrupted else ''}")
    for f in summary["failing_runs"][:5]:
        print(f"  replay: {f['replay']}")
    if len(summary["failing_runs"]) > 5:
        print(f"  ... {len(summary['failing_runs']) - 5} more in {out / 'index.html'}")
    print(f"report: {out / 'index.html'} (results.csv, plots)")
    if result.interrupted:
        return 130
    return 1 if args.strict and summary["failed"] else 0


def check_command(args: argparse.Namespace) -> int:
    from lowerbase.campaign.plan import load_campaign

    c = load_campaign(args.campaign)
    print(f"{args.campaign}: ok ({c.total} runs: {len(c.scenarios)} scenario(s) x "
          f"{c.grid_size} grid point(s) x {c.runs}; {len(c.variations)} varied value(s))")
    return 0


def replay_command(args: argparse.Namespace) -> int:
    from lowerbase.campaign.plan import build_scenario, load_campaign, plan_run
    from lowerbase.campaign.toml_out import dumps
    from lowerbase.cli.args import check_outputs
    from lowerbase.cli.scenario import run_loaded

    campaign = load_campaign(args.campaign)
    spec = plan_run(campaign, args.run)
    out = Path(args.out) if args.out else Path("reports") / (
        f"{campaign.name}-run{args.run}-{time.strftime('%Y%m%d-%H%M%S')}")
    check_outputs(args, out)
    scenario = build_scenario(spec, out)  # writes out/profile.toml when the run varies it
    out.mkdir(parents=True, exist_ok=True)
    (out / "scenario.toml").write_text(dumps(spec.data), encoding="utf-8")
    (out / "run.json").write_text(json.dumps(
        {"campaign": str(campaign.source), "run": spec.index, "scenario": spec.scenario,
         "values": spec.values, "seeds": spec.seeds}, indent=2) + "\n", encoding="utf-8")
    print(f"campaign {campaign.name} run {spec.index} ({spec.scenario}): " + ", ".join(
        f"{k} = {v:.6g}" if isinstance(v, float) else f"{k} = {v}"
        for k, v in spec.values.items()), file=sys.stderr)
    if spec.kind == "trace":
        from lowerbase.scenarios.trace import report, run_trace_scenario

        result = run_trace_scenario(scenario)
        print(report(result))
        print(f"run: {out / 'run.json'}")
        return 0 if result.passed else 1
    ns = argparse.Namespace(mode="simulated", record=None, mcap=args.mcap, foxglove=None,
                            progress=args.progress, status=False, debug=args.debug)
    return run_loaded(ns, scenario, out)
