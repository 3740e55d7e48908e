"""Configuration of the VAL II serial arm driver (config section ``arm`` with ``type: val``).

Every command string is a template here, never hard-wired in the driver: the hardware notes
confirm ``where``, ``speed`` and ``do move trans(...)`` on a real PUMA 260; the gripper and halt
commands and the error texts are standard VAL II but unconfirmed, so check them on the
controller and override them in YAML.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

# Values used to check that every template formats (the field names each template may use).
_TEMPLATE_FIELDS: dict[str, dict[str, float]] = {
    "where": {},
    "speed": {"percent": 50.0},
    "move": {"x_mm": 1.0, "y_mm": 2.0, "z_mm": 3.0, "o_deg": 4.0, "a_deg": 5.0, "t_deg": 6.0},
    "gripper_open": {},
    "gripper_close": {},
    "halt": {},
    "edit": {"program": "p"},
    "edit_end": {},
    "listing": {"program": "p"},
    "execute": {"program": "p"},
    "set_location": {"name": "p", "x_mm": 1.0, "y_mm": 2.0, "z_mm": 3.0, "o_deg": 4.0,
                     "a_deg": 5.0, "t_deg": 6.0},
}
# The fields a program line may use.
_PROGRAM_FIELDS = {"input": 1001, "guard_speed": 25.0, "rest_mm": 9.0, "lift_mm": 10.0}
# The programs a descent runs: without a lift, and with the close and the lift.
DESCENT_PROGRAM = "fpdesc"
GRIP_PROGRAM = "fpgrip"


@dataclass(frozen=True)
class ValCommands:
    """Command templates (``str.format`` fields in braces), sent without the line ending.

    where: read the pose (confirmed). speed: monitor speed, field ``percent`` (confirmed).
    move: absolute Cartesian move, fields ``x_mm y_mm z_mm o_deg a_deg t_deg`` (confirmed).
    gripper_open / gripper_close / halt: unconfirmed standard VAL II.
    edit / edit_end / listing / execute (field ``program``): enter a program line by line,
    end the editor, list a program, run it (VAL's EDIT, E, LISTP, EXECUTE: documented,
    spelling unconfirmed); set_location: set a named location to a pose (field ``name`` and
    the pose fields; VAL II's SET, unconfirmed).
    """

    where: str = "where"
    speed: str = "speed {percent:g}"
    move: str = ("do move trans({x_mm:.2f},{y_mm:.2f},{z_mm:.2f},"
                 "{o_deg:.3f},{a_deg:.3f},{t_deg:.3f})")
    gripper_open: str = "do openi"
    gripper_close: str = "do closei"
    halt: str = "abort"
    edit: str = "edit {program}"
    edit_end: str = "e"
    listing: str = "listp {program}"
    execute: str = "ex {program}"
    set_location: str = ("do set {name}=trans({x_mm:.2f},{y_mm:.2f},{z_mm:.2f},"
                         "{o_deg:.3f},{a_deg:.3f},{t_deg:.3f})")

    def __post_init__(self) -> None:
        for name, sample in _TEMPLATE_FIELDS.items():
            template = getattr(self, name)
            try:
                text = template.format(**sample)
            except (KeyError, IndexError, ValueError) as exc:
                raise ValueError(f"{name}: template {template!r} does not format with the "
                                 f"fields {sorted(sample) or 'none'}: {exc!r}") from exc
            if not text.strip() or not text.isascii() or any(c in text for c in "\r\n"):
                raise ValueError(f"{name}: template {template!r} must give one non-empty "
                                 "ASCII line")


@dataclass(frozen=True)
class ValConfig:
    """How to reach and talk to the VAL II monitor.

    port: a ``serial.serial_for_url`` URL: a device (``/dev/ttyS0``), a pty (``/dev/pts/7``),
        ``socket://host:port``, ``spy://...`` or ``loop://``.
    baudrate / bytesize / parity / stopbits: the line format (PUMA 260: 9600 8N1).
    line_ending: what ends a command (``"\\r"``; one public driver sends ``"\\n\\r"``).
    echo: the monitor echoes each command line; a reply must start with that echo.
    exchange_timeout_s: longest wait for the reply to one command.
    move_timeout_s: longest wait for a motion to finish (the prompt after ``do move``).
    where_after_move: read the pose back with ``where`` after every move and report that
        (costs 262 bytes, 273 ms at 9600 baud); off (default): a move's prompt means it is done
        (confirmed), so the target is reported.
    where_before_move: start every move (and its safety check) from a fresh ``where``; off
        (default): from the pose the last completed move reached (its target: the prompt
        confirms it done; the arm's repeatability, about 0.05 mm, is the difference), and a
        ``where`` only after a halt, a fault, a reset, a refused or failed move. Off also skips
        ``openi`` for jaws the driver itself opened last. The hardware notes call a fresh
        ``where`` the safest start of a relative move; turn this on when anything else (a
        pendant, another program) may move the arm between the driver's commands.
    boot_answers: start-up questions (matched case-insensitively as a part of the question
        line) and the answer sent to each; any other question during start-up is an error.
    rejection_errors: controller error texts (part of the ``*...*`` message, any case) that mean
        "refused, nothing moved" (MotionRejectedError); every other error is a fault.
    gripper_open_width_mm / gripper_closed_width_mm: nominal finger widths reported after
        open/close (VAL has no finger feedback).
    max_segment_mm / max_segment_deg: a move longer than this (translation, or any of O, A, T)
        is sent as equal ``do move`` segments, each waited for (moves block: confirmed), so a
        halt stops the arm at the end of the segment under way by simply not sending the next
        one (whether VAL's ``abort`` stops a running ``do move`` has no source). 0 for both
        (the default, so timing fits see whole moves): never split; deploy/finepos.yaml sets
        20 mm / 10 deg (a judgement: a few hundred ms per segment). A target the controller
        refuses may then be refused after the first segments have moved.
    commands: the command templates.
    programs: run the grasp's guarded descent, and with it the close and the lift, as a
        program on the controller (one ``execute`` per grasp, stopped by ``REACTI`` on
        ``program_input``, the line that carries the wrist sensor's monitor output); the
        programs are downloaded when the arm connects, checked by listing them back and
        entered again where a listing differs; a program VAL refuses, or one that lists back
        otherwise, fails the connection naming the program and the line. false: one monitor
        command per move.
    program_input: the VAL input line wired to the sensor's discrete output.
    program_guard_speed: the program speed (percent) the descent program is entered with; a
        descent asking for another enters it again.
    program_contact_text: what the reaction subroutine types when the input stopped the arm.
    program_lines: the programs, name -> lines (``str.format`` fields ``input``,
        ``guard_speed``, ``rest_mm`` and ``lift_mm``). The descent program ``fpdesc`` moves to
        location ``fpa`` at full speed, at the guard speed to ``rest_mm`` before ``fpd`` along
        its approach axis (``APPROS``), then to ``fpd`` at full speed; it must open the jaws as
        it starts and arm ``REACTI`` on the input before moving. ``fpgrip`` (optional; without
        it the host closes and lifts) descends the same way, then arms the input again with
        ``fpjam``, closes the jaws (``CLOSEI``: after the motion, then the hand time) and lifts
        ``lift_mm`` (``DEPARTS``); a reaction types ``program_contact_text`` (on the way down)
        or ``program_jam_text`` (after the close). A grasp whose ``guard_speed``, ``rest_mm``
        or ``lift_mm`` differs from the text on the controller enters its program again (a
        part taught to another depth: once). Instruction spellings are VAL II's as
        documented, unconfirmed on a wire: check them on the controller.
    program_jam_text: what the reaction subroutine after the close types (the input went
        high once the jaws closed: a finger pushing on the part).
    """

    port: str
    baudrate: int = field(default=9600, metadata={"min": 50})
    bytesize: Literal[5, 6, 7, 8] = 8
    parity: Literal["N", "E", "O", "M", "S"] = "N"
    stopbits: Literal[1, 2] = 1
    line_ending: Literal["\r", "\n", "\r\n", "\n\r"] = "\r"
    echo: bool = True
    exchange_timeout_s: float = field(default=2.0, metadata={"min": 0.0, "exclusive_min": True})
    move_timeout_s: float = field(default=60.0, metadata={"min": 0.0, "exclusive_min": True})
    where_after_move: bool = False
    where_before_move: bool = False
    boot_answers: dict[str, str] = field(default_factory=lambda: {
        "Load VAL from floppy": "n",
        "Initialize": "n",
    })
    rejection_errors: tuple[str, ...] = ("position out of range",)
    gripper_open_width_mm: float = field(default=40.0, metadata={"min": 0.0})
    gripper_closed_width_mm: float = field(default=0.0, metadata={"min": 0.0})
    max_segment_mm: float = field(default=0.0, metadata={"min": 0.0})
    max_segment_deg: float = field(default=0.0, metadata={"min": 0.0})
    commands: ValCommands = field(default_factory=ValCommands)
    programs: bool = False
    program_input: int = field(default=1001, metadata={"min": 1})
    program_guard_speed: float = field(default=10.0, metadata={"min": 0.01, "max": 100.0})
    program_contact_text: str = "FPCONTACT"
    program_jam_text: str = "FPJAM"
    program_lines: dict[str, tuple[str, ...]] = field(default_factory=lambda: {
        "fpstop": ("TYPE FPCONTACT", "STOP"),
        "fpjam": ("TYPE FPJAM", "STOP"),
        DESCENT_PROGRAM: ("SPEED 100", "OPEN", "REACTI {input}, fpstop", "MOVES fpa",
                          "SPEED {guard_speed:g}", "APPROS fpd, {rest_mm:.2f}", "SPEED 100",
                          "MOVES fpd", "IGNORE {input}"),
        GRIP_PROGRAM: ("SPEED 100", "OPEN", "REACTI {input}, fpstop", "MOVES fpa",
                       "SPEED {guard_speed:g}", "APPROS fpd, {rest_mm:.2f}", "SPEED 100",
                       "MOVES fpd", "REACTI {input}, fpjam", "CLOSEI",
                       "DEPARTS {lift_mm:.2f}", "IGNORE {input}"),
    })

    def program_text(self, guard_speed: float | None = None, rest_mm: float = 0.0,
                     lift_mm: float = 10.0, run: str | None = None
                     ) -> dict[str, tuple[str, ...]]:
        """The programs as entered on the controller (fields filled in); ``run``: only that
        main program (``fpdesc`` or ``fpgrip``) of the two, with every other program."""
        speed = self.program_guard_speed if guard_speed is None else guard_speed
        skipped = {DESCENT_PROGRAM, GRIP_PROGRAM} - {run} if run is not None else set()
        return {name: tuple(line.format(input=self.program_input, guard_speed=speed,
                                        rest_mm=rest_mm, lift_mm=lift_mm)
                            for line in lines)
                for name, lines in self.program_lines.items() if name not in skipped}

    def __post_init__(self) -> None:
        if not self.port.strip():
            raise ValueError("port: must name a serial port URL, got an empty string")
        if self.gripper_closed_width_mm >= self.gripper_open_width_mm:
            raise ValueError("gripper_closed_width_mm must be below gripper_open_width_mm, got "
                             f"{self.gripper_closed_width_mm} / {self.gripper_open_width_mm}")
        for question, answer in self.boot_answers.items():
            if not question.strip() or not answer.isascii() or any(c in answer for c in "\r\n"):
                raise ValueError(f"boot_answers: bad entry {question!r}: {answer!r}")
        if (self.max_segment_mm == 0) != (self.max_segment_deg == 0):
            raise ValueError("max_segment_mm and max_segment_deg: both 0 (never split) or both "
                             f"above 0, got {self.max_segment_mm} / {self.max_segment_deg}")
        if any(not text.strip() for text in self.rejection_errors):
            raise ValueError("rejection_errors: entries must not be empty")
        if self.programs and DESCENT_PROGRAM not in self.program_lines:
            raise ValueError(f"program_lines: the descent program {DESCENT_PROGRAM!r} is "
                             "missing")
        for name, lines in self.program_lines.items():
            for i, line in enumerate(lines, 1):
                try:
                    text = line.format(**_PROGRAM_FIELDS)
                except (KeyError, IndexError, ValueError) as exc:
                    raise ValueError(f"program_lines.{name}[{i}]: {line!r} does not format "
                                     f"with the fields input, guard_speed, rest_mm, "
                                     f"lift_mm: "
                                     f"{exc!r}") from exc
                if not text.strip() or not text.isascii() or any(c in text for c in "\r\n"):
                    raise ValueError(f"program_lines.{name}[{i}]: must be one ASCII line")
