"""``finepos teach | acquire | train | rezero | position | grasp``: the cell's workflow, step by
step.

Each works on one part (``--part``, see ``common.part_setup``), in that part's folder under the
state folder (``controller.teach.state_folder``), which it locks for its run against a service
or another of them (``controller.teach.state_lock``).
"""

from __future__ import annotations

import contextlib

from calibration_free.rezero import MAX_SHIFT_MM, MAX_TURN_DEG, NN2_MIN_DEG
from controller.calibration.rezero import REZERO_FRAMES, REZERO_SYSTEMS
from controller.commands.common import (
    TAUGHT_PART_HELP,
    add_command,
    add_config_option,
    add_log_option,
    add_part_option,
    add_record_option,
    add_system_option,
    config_from_args,
    iteration_log,
    loop_budget,
    parse_triple,
    part_setup,
    positive_float,
    positive_int,
    run_recorder,
    state_root,
)
from controller.commands.device_options import add_device_options, apply_device_options
from controller.devices import open_devices
from controller.fine_positioner import DATASETS, FinePositioner
from controller.recipe import load_recipe
from controller.teach.spacenav import DEFAULT_SIM_START_OFFSET, TeachAborted, teach_with_spacenav
from controller.teach.state_lock import locked_state_folder
from drivers.core.errors import ConfigError
from drivers.core.files import write_json
from drivers.core.pose import ToolStep

_SPACENAV_ONLY = ("start_offset", "spnav_socket", "timeout_s")


@contextlib.contextmanager
def _locked_setup(args, command: str, *, teach: bool = False, devices: bool = True):
    """The config file's settings (with the command line's device options applied, unless not
    ``devices``) set up for the command's part, and that part's state folder
    (``common.part_setup``), with the state folder locked against other writers for the block.

    Raises:
        StateFolderLocked: a service or another writer holds the state folder (exit status 2).
    """
    config = config_from_args(args)
    if devices:
        config = apply_device_options(config, args)
    with locked_state_folder(state_root(args, config), f"finepos {command}", create=teach):
        yield part_setup(args, config, teach=teach)


def cmd_teach(args) -> int:
    """Record the nominal pose (auto, spacenav or current); 1 when a spacenav teach-in aborts."""
    given = [f"--{name.replace('_', '-')}" for name in _SPACENAV_ONLY
             if getattr(args, name) is not None]
    if given and args.device != "spacenav":
        raise ConfigError(f"{given[0]}: only with --device spacenav")
    start_offset = parse_triple(args.start_offset, "--start-offset") if args.start_offset \
        else None
    with _locked_setup(args, "teach", teach=True) as (config, state_dir), \
            open_devices(config) as devices:
        fp = FinePositioner(devices, config, state_dir=state_dir)
        if args.auto:
            state = fp.teach_auto(kappa=args.kappa)
        elif args.device == "spacenav":
            try:
                state = teach_with_spacenav(
                    fp, start_offset=start_offset, socket_path=args.spnav_socket,
                    grasp_depth_mm=args.grasp_depth_mm, object_width_mm=args.object_width_mm,
                    timeout_s=args.timeout_s)
            except TeachAborted as exc:
                write_json(None, {"part": config.controller.part,
                                  "state_file": str(fp.state_path), "aborted": True,
                                  "reason": str(exc)})
                return 1
        else:
            state = fp.teach("current", args.grasp_depth_mm, args.object_width_mm,
                             kappa=args.kappa)
    write_json(None, {"part": state.object_kind, "state_file": str(fp.state_path),
                      "nominal_pose": state.nominal_pose.as_dict(), "object": state.object_kind,
                      "kappa": state.kappa, "source": state.source,
                      "kappa_found": state.kappa_found})
    return 0


def cmd_acquire(args) -> int:
    """Take the ``--set`` dataset around the taught pose and print where it is stored."""
    with _locked_setup(args, "acquire") as (config, state_dir), open_devices(config) as devices:
        fp = FinePositioner(devices, config, state_dir=state_dir)
        data = fp.acquire(args.set, seed=args.seed)
    write_json(None, {"part": config.controller.part, "set": args.set, "images": len(data),
                      "file": str(fp.dataset_path(args.set)),
                      "seconds": data.metadata.get("seconds")})
    return 0


def cmd_train(args) -> int:
    """Train ``--system`` from the nn1 and nn2 datasets and print the model file."""
    recipe = load_recipe(args.recipe) if args.recipe is not None else None
    with _locked_setup(args, "train", devices=False) as (config, state_dir):
        fp = FinePositioner(None, config, state_dir=state_dir)
        model = fp.train(args.system, recipe)
    write_json(None, {"part": config.controller.part, "system": args.system,
                      "model": str(fp.model_path(args.system)),
                      "recipe": args.recipe or "kept",
                      "train_images": model.train_images,
                      "train_seconds": round(model.train_seconds, 3)})
    return 0


def cmd_rezero(args) -> int:
    """Re-zero the part's model (``--system``: gabor or align) at the taught pose in the
    cell's light; print what moved."""
    if args.heading_range and args.heading_step is None:
        raise ConfigError("--heading-range: only with --heading-step")
    with _locked_setup(args, "rezero") as (config, state_dir), open_devices(config) as devices:
        fp = FinePositioner(devices, config, state_dir=state_dir)
        _, report = fp.rezero(args.frames, args.system, args.heading_step,
                              tuple(args.heading_range) if args.heading_range else None)
    write_json(None, {"part": config.controller.part, "system": args.system,
                      "model": str(fp.model_path(args.system)), **report})
    return 0


def cmd_position(args) -> int:
    """Run the positioning loop (then ``--grasp``); 1 unless it converged or used its budget.

    The model is loaded before the iteration log and the recording are created: a run that
    cannot start leaves no files."""
    offset = parse_triple(args.offset, "--offset") if args.offset is not None else None
    with _locked_setup(args, "position") as (config, state_dir), \
            open_devices(config) as devices:
        fp = FinePositioner(devices, config, state_dir=state_dir)
        fp.load_model(args.model, args.system)
        with iteration_log(args, config) as log, run_recorder(args) as recorder:
            fp.log, fp.recorder = log, recorder
            report = _position_run(args, fp, offset)
    ok = report.pop("ok")
    write_json(None, report)
    return 0 if ok else 1


def _position_run(args, fp: FinePositioner, offset) -> dict:
    """The positioning run (and grasp) of ``finepos position``, as its JSON report plus
    ``ok`` (converged or budget spent; taken out before printing)."""
    if offset is not None:
        dx, dy, dphi = offset
        fp.move_to(fp.state().nominal_pose.moved_in_tool_frame(
            ToolStep(-dx, -dy, 0.0, -dphi)))
    result = fp.position(args.max_loops, then_grasp=args.grasp)
    # the grasp makes the converged step with its first move, and adds it to the run
    grasp = fp.grasp().as_dict() if args.grasp and result.ok else None
    report = {"part": fp.config.controller.part, "run_id": result.run_id,
              "outcome": result.outcome, "reason": result.reason,
              "loops": result.loops, "iterations": result.iterations,
              "error": result.states[-1].error, "log": str(fp.log.path)}
    if args.record:
        report["record"] = args.record
    if grasp is not None:
        report["grasp"] = grasp
    report["ok"] = result.ok
    return report


def cmd_grasp(args) -> int:
    """Run the force-guarded grasp from the current pose; 1 when it failed."""
    with _locked_setup(args, "grasp") as (config, state_dir), open_devices(config) as devices, \
            run_recorder(args) as recorder:
        fp = FinePositioner(devices, config, state_dir=state_dir, recorder=recorder)
        result = fp.grasp()
    write_json(None, {"part": config.controller.part, **result.as_dict()})
    return 0 if result.success else 1


def register(subparsers) -> None:
    """Add ``finepos teach``, ``acquire``, ``train``, ``rezero``, ``position`` and ``grasp``."""
    p = add_command(
        subparsers, "teach",
        help="record the nominal grasp pose into the cell's state file",
        description="Example: finepos teach --auto\n\nRecord the nominal pre-grasp pose. "
                    "--auto (simulated cell): place the gripper at the part's true grasp "
                    "pose; --device spacenav: jog with the 3D mouse through spacenavd "
                    "(controller.teach: button 0 records, button 1 aborts and writes nothing, "
                    "exit status 1); otherwise the arm's current pose is recorded.\n\n"
                    "Example: finepos teach --device spacenav --start-offset 4,-3,5\n\n"
                    "Each part is taught into its own folder under the state folder "
                    "(state/<part>/cell.json); --part NAME teaches that part (on the simulated "
                    "cell it is put on the table first).\n\n"
                    "Example: finepos teach --auto --part nut\n\n"
                    "A part declared without kappa has it found from its own images: the tool "
                    "turns a full turn at the taught pose; where the evidence is weak teach "
                    "refuses to guess and names its best guess: confirm it with --kappa N.")
    add_config_option(p)
    add_device_options(p)
    add_part_option(p, "the cell's: the simulated table's, or controller.part")
    how = p.add_mutually_exclusive_group()
    how.add_argument("--auto", action="store_true", help="simulated cell: the true pose")
    how.add_argument("--device", choices=["spacenav"], help="jog with a 3D mouse")
    p.add_argument("--grasp-depth-mm", type=float,
                   help="descent from the pose to grip (default: the part's, controller.part)")
    p.add_argument("--object-width-mm", type=float,
                   help="finger width when holding the part (default: the part's)")
    p.add_argument("--kappa", type=positive_int,
                   help="the part's rotational symmetry, confirmed (default: the declared one, "
                        "else found from the part's images)")
    default_offset = ",".join(f"{v:g}" for v in DEFAULT_SIM_START_OFFSET)
    p.add_argument("--start-offset", metavar="DX,DY,DPHI",
                   help="spacenav on the simulated cell: start this far from the grasp pose "
                        f"(mm, mm, deg; default {default_offset})")
    p.add_argument("--spnav-socket", metavar="PATH",
                   help="spacenavd's socket (default: controller.teach.socket_path, "
                        "$SPNAV_SOCKET, /var/run/spnav.sock)")
    p.add_argument("--timeout-s", type=float,
                   help="spacenav: give up after this long without a record (nothing written)")
    p.set_defaults(func=cmd_teach)

    p = add_command(
        subparsers, "acquire",
        help="take the training or test images around the taught pose",
        description="Example: finepos acquire --set nn1\n\nDrive the grid of displacements "
                    "(nn1: a = 25 mm, nn2: a = 5 mm, b = 180/kappa deg, 3x3x7; each first "
                    "takes controller.acquisition.taught_pose_frames frames, 4, at the taught "
                    "pose, each after leaving it by 1 mm and coming back) or a random test "
                    "set, and store the dataset in the part's state folder "
                    "(state/<part>/datasets/<set>.npz).")
    add_config_option(p)
    add_device_options(p)
    add_part_option(p, TAUGHT_PART_HELP)
    p.add_argument("--set", required=True, choices=DATASETS)
    p.add_argument("--seed", type=int, default=0, help="seed of the random test set")
    p.set_defaults(func=cmd_acquire)

    p = add_command(
        subparsers, "train",
        help="train NN1 and NN2 into a model bundle",
        description="Example: finepos train --recipe recipe.yaml\n\nTrain the system from "
                    "the nn1 and nn2 datasets into the part's state folder "
                    "(state/<part>/model-<system>...). The model file keeps the recipe it was "
                    "trained with (the perception settings and the loop's tuned keys, "
                    "docs/configuration.md#recipe), and runs with it.")
    add_config_option(p)
    add_part_option(p, TAUGHT_PART_HELP)
    add_system_option(p)
    p.add_argument("--recipe", metavar="FILE",
                   help="train with this recipe (YAML: perception and loop sections; keys "
                        "left out take their defaults; an empty file: all defaults). "
                        "Without it: the recipe of the current model file, the defaults where "
                        "there is none")
    p.set_defaults(func=cmd_train)

    p = add_command(
        subparsers, "rezero",
        help="re-zero the part's model at the taught pose in the cell's light",
        description="Example: finepos rezero\n\nAfter the light changed (a lamp moved, the "
                    "room dimmed): with the part where it was taught, move to the taught "
                    "pose, take --frames frames and shift the translation nets to read zero "
                    "there (on the frames' means, as many at a time as the loop's settling "
                    "look reads where single frames scatter as these do: the report's "
                    "frame_scatter, mm, mm, deg, and average), and turn NN2 back where it reads "
                    f"{NN2_MIN_DEG:g} deg or more there (the Gabor model in the part's "
                    "state folder, rewritten atomically; no new acquisition; --system "
                    "align: take the servo's template again there). A reading over "
                    f"{MAX_SHIFT_MM:g} mm or "
                    f"{MAX_TURN_DEG:g} deg there is refused: the part is not where it was "
                    "taught, or the camera moved. The report's clipped_share is the share of "
                    "the part's pixels with a channel at 255 there; over 5% a warning says to "
                    "bring the camera's exposure down "
                    "(docs/decisions/0013-expose-for-the-part.md); "
                    "where single frames scatter more than the settling look's "
                    "recipe's loop.settle_max_frames can average within its bounds, "
                    "another says to lower its gain.\n\n"
                    "Also: finepos rezero --heading-step 5\n\n"
                    "--heading-step DEG: then also read the zero by heading (gabor): a lamp "
                    "at the side lights the part from another side at each heading, and the "
                    "step read at the taught pose turns with it. The arm grasps the part, "
                    "turns it, sets it down and reads NN2's turn from the taught pose turned "
                    "with it, at headings at most DEG apart over --heading-range FROM TO (the "
                    "part's turn from its taught heading, deg; default one symmetry period "
                    "centred on it: -45 45 for the cube; the whole turn less one step for the "
                    "screw), and puts it back, and reads the translation as well: the cube it "
                    "centres by closing the jaws on it turned by a quarter turn after each "
                    "set-down; the other parts it turns back to the taught heading after each "
                    "heading and looks there too, which says how far the set-downs moved them. "
                    "The loop then takes the zero at the tool's heading off each full look's "
                    "step. About 20 s a heading (the centring or the turn back doubles the 9 s "
                    "of a grasp, a turn, a set-down and a look; --heading-range or a larger "
                    "step for less); the gripper must be able to grasp the part there. "
                    "A plain rezero drops the zero by heading (it belongs to the old light).")
    add_config_option(p)
    add_device_options(p)
    add_part_option(p, TAUGHT_PART_HELP)
    p.add_argument("--frames", type=int, default=REZERO_FRAMES,
                   help=f"frames at the taught pose (default {REZERO_FRAMES}; more where the "
                        "settling look's bounds ask for more frames a mean: two whole means "
                        "at least, see the recipe's loop.settle_sem_mm)")
    p.add_argument("--system", default="gabor", choices=REZERO_SYSTEMS,
                   help="the model to re-zero: gabor (the default) or align (the "
                        "image-alignment servo)")
    p.add_argument("--heading-step", type=positive_float, metavar="DEG",
                   help="also read the zero by heading, in steps of at most DEG (see above)")
    p.add_argument("--heading-range", type=float, nargs=2, metavar=("FROM", "TO"),
                   help="with --heading-step: the part's turns from its taught heading, deg "
                        "(default: one symmetry period centred on it)")
    p.set_defaults(func=cmd_rezero)

    p = add_command(
        subparsers, "position",
        help="run the fine-positioning loop (and optionally grasp)",
        description="Example: finepos position --offset 12,-8,20 --grasp\n\nRun the half/full "
                    "loop from where the arm is; --offset first moves the arm to the taught "
                    "pose displaced by it (mm, mm, deg; through the safety layer).\n\n"
                    "Hardware in the loop (after finepos sim val-emulator --ati --mjpeg 0):\n"
                    "  finepos position --arm val --port /dev/pts/3 --wrench ati "
                    "--wrench-port /dev/pts/4\n"
                    "    --camera http://127.0.0.1:8080/stream.mjpg --offset 12,-8,20 --grasp")
    add_config_option(p)
    add_device_options(p)
    add_log_option(p)
    add_record_option(p)
    add_part_option(p, TAUGHT_PART_HELP)
    add_system_option(p)
    p.add_argument("--model", metavar="FILE", help="model file (default: the state folder's)")
    p.add_argument("--offset", metavar="DX,DY,DPHI",
                   help="first move to the taught pose displaced by this (mm, mm, deg)")
    p.add_argument("--max-loops", type=loop_budget, help="loop budget (default from config)")
    p.add_argument("--grasp", action="store_true",
                   help="then grasp (where the loop converged or spent its budget), the "
                        "converged step made by the grasp's first descent move")
    p.set_defaults(func=cmd_position)

    p = add_command(
        subparsers, "grasp",
        help="force-guarded grasp from the current pose",
        description="Example: finepos grasp\n\nDescend with the wrist sensor guarding, close, "
                    "verify the grip, lift. --record FILE.mcap records every wrench "
                    "reading and how the grasp ended.")
    add_config_option(p)
    add_device_options(p)
    add_record_option(p)
    add_part_option(p, TAUGHT_PART_HELP)
    p.set_defaults(func=cmd_grasp)
