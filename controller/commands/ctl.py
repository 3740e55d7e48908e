"""``finepos ctl``: the control API's command-line client (see ``controller.service``).

The subcommands and their options are generated from ``controller.service.commands.COMMANDS``, so
the client and the service cannot disagree about them. Every job command takes ``--part NAME``
(default: the one part taught; teach: the cell's part). Job commands wait for the job to end
(``--no-wait``: only start it). The result is printed as JSON; the exit status is 0, or 1 for an
error response or a job that did not end ``done``.
"""

from __future__ import annotations

import argparse
import json
import math
import sys

from controller.commands.common import parse_triple
from controller.service.client import ServiceClient, ServiceError
from controller.service.commands import COMMANDS, JOB_COMMANDS, REQUIRED, Arg
from controller.service.config import ServiceConfig
from controller.service.listeners import read_token
from drivers.core.errors import ConfigError

DEFAULT_SOCKET = ServiceConfig.socket_path
# Subcommand: (runnable example, what it does).
LEAVES = {
    "status": ("finepos ctl status", "state, pose, job, last iteration, taught parts and "
               "their models in use, fault"),
    "teach": ("finepos ctl teach --auto --part nut", "record the nominal pose of a part "
              "(--auto: simulated cell; otherwise the arm's current pose)"),
    "acquire": ("finepos ctl acquire --set nn1 --part nut", "take a training or test set"),
    "train": ("finepos ctl train --system gabor --part nut", "train a model from nn1 and nn2"),
    "rezero": ("finepos ctl rezero --part nut", "re-zero a part's model at the taught pose "
               "in the cell's light (the part where it was taught)"),
    "position": ("finepos ctl position --offset 12,-8,20 --part nut",
                 "run the positioning loop"),
    "grasp": ("finepos ctl grasp --part nut", "force-guarded grasp from the current pose"),
    "abort": ("finepos ctl abort", "preempt the running job and halt the arm"),
    "reload": ("finepos ctl reload", "load the models of the taught parts from the state "
               "folder into use"),
    "reset": ("finepos ctl reset", "leave fault once the cause is gone"),
    "stream": ("finepos ctl stream --count 20", "print iteration records and state changes"),
}


def _client(args) -> ServiceClient:
    if args.tcp is None:
        return ServiceClient(args.socket, timeout_s=args.timeout)
    host, _, port = args.tcp.rpartition(":")
    port_ok = port.isascii() and port.isdigit() and 1 <= int(port) <= 65535
    if not host or not port_ok or not args.token_file:
        raise ConfigError(f"--tcp: expected HOST:PORT (port 1..65535) and --token-file FILE, "
                          f"got {args.tcp!r}")
    token = read_token(args.token_file)
    return ServiceClient(tcp=(host, int(port)), token=token, timeout_s=args.timeout)


def _request_args(args, specs: dict[str, Arg]) -> dict:
    values = {}
    for name, spec in specs.items():
        if name == "wait":
            values[name] = not args.no_wait
            continue
        value = getattr(args, name)
        if value is None or value is False:
            continue
        values[name] = list(parse_triple(value, f"--{name}")) if spec.kind is list else value
    return values


def cmd_ctl(args) -> int:
    """Send one command and print the result as JSON; 1 for an error or a job not ``done``."""
    with _client(args) as client:
        if args.ctl_command == "stream":
            return _stream(client, args.count)
        job_timeout = None if args.ctl_command in JOB_COMMANDS and not args.no_wait else \
            args.timeout
        try:
            result = client.call(args.ctl_command, timeout_s=job_timeout,
                                 **_request_args(args, COMMANDS[args.ctl_command]))
        except ServiceError as exc:
            print(f"finepos ctl: {exc.code}: {exc.message}", file=sys.stderr)
            return 1
    print(json.dumps(result, indent=2))
    job = result.get("job") if isinstance(result, dict) else None
    return 1 if job and job.get("outcome") not in (None, "done") else 0


def _stream(client: ServiceClient, count: int | None) -> int:
    for n, event in enumerate(client.events(), 1):
        print(json.dumps(event), flush=True)
        if count is not None and n >= count:
            break
    return 0


def _positive_seconds(text: str) -> float:
    """``--timeout``: a positive, finite number of seconds."""
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and value > 0):
        raise argparse.ArgumentTypeError(f"expected a positive number of seconds, got {text!r}")
    return value


def _positive_count(text: str) -> int:
    """``--count``: a whole number of at least 1."""
    if not (text.isascii() and text.strip().isdigit()) or int(text) < 1:
        raise argparse.ArgumentTypeError(f"expected a whole number >= 1, got {text!r}")
    return int(text)


def _add_option(parser: argparse.ArgumentParser, name: str, spec: Arg) -> None:
    flag = "--" + name.replace("_", "-")
    if spec.kind is bool:
        parser.add_argument(flag, dest=name, action="store_true", help=spec.help)
        return
    parser.add_argument(flag, dest=name, type=str if spec.kind is list else spec.kind,
                        choices=spec.choices or None, required=spec.default is REQUIRED,
                        metavar="DX,DY,DPHI" if spec.kind is list else None, help=spec.help)


def register(subparsers) -> None:
    """Add ``finepos ctl`` with one leaf per control command (options from COMMANDS)."""
    p = subparsers.add_parser(
        "ctl", help="command a running `finepos serve` over its control socket",
        description="Example: finepos ctl status\n\nSend one command to the service and print "
                    "the result as JSON.",
        formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--socket", default=DEFAULT_SOCKET, metavar="PATH",
                   help=f"the service's control socket (default {DEFAULT_SOCKET})")
    p.add_argument("--tcp", metavar="HOST:PORT", help="use the loopback TCP listener instead")
    p.add_argument("--token-file", metavar="FILE", help="the TCP listener's token file")
    p.add_argument("--timeout", type=_positive_seconds, default=30.0, metavar="S",
                   help="seconds to wait for an answer (job commands that wait: no limit)")
    sub = p.add_subparsers(dest="ctl_command", metavar="COMMAND", required=True)
    for name, (example, what) in LEAVES.items():
        specs = COMMANDS[name]
        leaf = sub.add_parser(name, help=what,
                              description=f"Example: {example}\n\n{what[0].upper()}{what[1:]}.",
                              formatter_class=argparse.RawDescriptionHelpFormatter)
        for arg_name, spec in specs.items():
            if arg_name != "wait":
                _add_option(leaf, arg_name, spec)
        if "wait" in specs:
            leaf.add_argument("--no-wait", action="store_true",
                              help="answer as soon as the job started")
        if name == "stream":
            leaf.add_argument("--count", type=_positive_count, metavar="N",
                              help="stop after N events (N >= 1)")
    p.set_defaults(func=cmd_ctl)
