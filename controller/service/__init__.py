"""The controller service (``finepos serve``) and its control API.

One long-running process owns the configured devices (the simulated cell unless configured
otherwise) and a FinePositioner, keeps one state machine (``states``) and runs one job at a time
in a worker thread. People and programs command it over a UNIX socket; ``finepos ctl`` is the
command-line client, ``client.ServiceClient`` the Python one.

Protocol: JSON lines. Each request is one UTF-8 JSON object on one line (at most
``service.max_request_bytes``, newline included); each gets exactly one response line, in order::

    {"id": 7, "cmd": "position", "args": {"max_loops": 4, "wait": true}}
    {"id": 7, "ok": true, "result": {"job": {"id": 3, "kind": "position", "outcome": "done", ...}}}
    {"id": null, "ok": false, "error": {"code": "bad_json", "message": "not a JSON request: ..."}}

``id`` (optional: a string of at most 64 characters, an integer or null) is echoed; ``args`` is
optional. Error codes are listed in ``protocol.ERROR_CODES`` (too_large, bad_json, bad_request,
unknown_command, unauthorized, too_many_clients, not_ready, busy, fault, stopping, failed). A bad
request never ends the connection.

Commands (arguments, types, ranges and defaults in ``commands.COMMANDS``):

- ``status``: state, since, reason, pid, uptime_s, job (running), last_job (with outcome,
  reason, result), pose (last read or reached, with its time), last_iteration (the latest
  iteration record), part (the part of the last job, else the cell's), model (that part's model
  in use: system, file, train images), parts (every taught part: its state folder and its model
  in use), fault (code, reason, since, devices not active, reconnected, reconnect_attempts),
  config (source, last_reload), iteration_log, clients;
- jobs, refused unless idle (``busy``, ``fault``, ``not_ready``, ``stopping``): ``teach``
  (``auto``: simulated cell only; otherwise the current pose, with the grasp geometry of
  ``controller.part`` unless ``grasp_depth_mm`` and ``object_width_mm`` are given), ``acquire``
  (``set``: nn1 | nn2 | test, ``seed``), ``train`` (``system``), ``rezero`` (``frames``, ``system``:
  gabor | align, ``heading_step``: also the zero by heading; re-zero the part's model at the
  taught pose in the cell's light, ``FinePositioner.rezero``; the part must lie where it was
  taught; it is put into use unless another system's model is),
  ``position`` (``max_loops``; ``offset`` [dx_mm, dy_mm, dphi_deg]: simulated cell only;
  ``grasp``: then grasp in the same job, where the loop converged or spent its budget, the
  converged look's step made by the grasp's first descent move,
  ``controller.grasp.carry_final_step``; the result holds the grasp's under ``grasp`` and a
  failed grasp fails the job), ``grasp``. Each takes ``part`` (cube | nut | ledge | screw;
  default: the one part taught, else the cell's; for ``teach`` the cell's: the simulated
  table's, or ``controller.part``; refused as ``bad_request`` when several parts are taught and
  none is named): the job works in that part's state folder with that part's model, and on the
  simulated cell the part is put on the table first (the cell is built anew with it). Every
  taught part's model stays loaded (one slot per part), so positioning another part loads
  nothing. Each takes ``wait``: false (default) answers when the job has started, true when it
  has ended; the job's ``outcome`` is done, failed (the reason says why, e.g. ``no_object: ...``
  or ``grasp failed: excessive force ...``), aborted, or fault;
- ``abort``: preempts the running job (no further motion command is sent) and halts the arm;
  it answers once the halt was acknowledged or after ``service.abort_wait_s`` (then
  ``halt_error`` says the halt is still waiting, and a ``halt`` event reports its outcome);
- ``reload``: loads the model of ``system`` (default: the one in use, else gabor) of ``part``
  (default: every taught part with a trained model) from the state folder (a bad one is
  refused and the old ones stay in use);
- ``reset``: in fault, reconnects the devices that are not active, reads each device once and
  returns to idle; refused (``fault``) while the cause is still there;
- ``stream``: answers once, then sends events, one per line, until the client disconnects:
  ``{"event": "iteration", "record": {...}}`` (the iteration log's records),
  ``{"event": "state", "state": ..., "previous": ..., "reason": ..., "time": ...}``,
  ``{"event": "dropped", "count": N}`` (the client read too slowly; the log file has them all),
  ``{"event": "halt", "ok": ..., "error": ...}`` (a halt that outlived its ``abort``),
  ``{"event": "job", "job": {...}, "time": ...}`` (a job ended; as ``status`` reports it),
  ``{"event": "abort", "job": ..., "halted": ..., "seconds": ..., "time": ...}`` (an
  ``abort`` answered: the job it preempted, whether the arm acknowledged the halt, how long
  the answer took),
  ``{"event": "fault", "code": ..., "reason": ..., "devices": {...}, "time": ...}`` (a fault
  entered or renewed; ``devices``: those not active, with their state),
  ``{"event": "end", ...}`` when the service stops, after every event published before it
  (a client that does not read meanwhile is cut off when the service closes);
- ``auth`` (``token``): the first request on a TCP connection.

Security: the socket is created with mode 0660 and group ``service.socket_group``; each peer's
credentials (SO_PEERCRED, SO_PEERGROUPS) must match the service's own user,
``service.allowed_users`` or ``service.allowed_groups``, else it gets one ``unauthorized`` line
and is disconnected. There is no network listener unless ``service.tcp`` is configured; that one
binds to loopback only and requires ``auth`` with the token from ``service.tcp.token_file``.
The metrics port (``service.metrics_port``, off by default) binds to loopback unless
``service.metrics_address`` names another address; then every scrape must send that token as
``Authorization: Bearer``.

Load and limits: ``status`` is answered from a snapshot rebuilt only when its inputs change
(``snapshot``); each connection's answers are paced to ``service.request_rate_hz`` after a burst
of ``request_burst`` (``pacing``; ``abort`` never is), so a fast poller slows only itself. A
connection silent for ``idle_timeout_s`` (streams excepted), or whose request line is not whole
``request_timeout_s`` after its first byte, is closed. At most ``max_clients`` connections, and
``max_clients_per_uid`` per peer uid, are served; an authorised peer over either limit may still
send one ``abort`` or ``status`` (answered by the accept thread, up to ``max_waiting`` such
peers at once, each for ``request_timeout_s``), so idle connections never lock out an abort.

Faults: ``status.fault.code`` is ``device`` (a device error; ``reset`` reconnects) or
``disk_full`` (the iteration log cannot be written; idle again by itself once there is room).
The service never exits on a device or file error.

systemd: READY=1 once serving, STATUS= on every state change, WATCHDOG=1 from the control loop,
STOPPING=1 on shutdown (``sd_notify``). SIGTERM halts and stops within
``service.stop_timeout_s``; SIGHUP reloads the config and the model (``config_reload`` says what
may change live; a file that cannot be loaded is refused and the old config stays). Exit
status: 0 after SIGTERM, 2 for a config that cannot be loaded at start (final under the unit's
``RestartPreventExitStatus=2``), 1 otherwise (restarted).

Modules: ``service`` (the Service: state, jobs, control loop), ``server`` and ``connection``
(the socket side), ``protocol`` and ``commands`` (wire format and validation), ``listeners``,
``peer`` (who may connect), ``jobs`` and ``model_slot`` (what jobs do), ``job_arm`` (the
preemptible arm), ``cell_connection`` (devices: open, recover, probe), ``events`` (the stream),
``states``, ``backoff``, ``pacing``, ``snapshot``, ``watchdog``, ``sd_notify``, ``signals``,
``config`` (the ``service:`` config section), ``config_reload``, ``client``, ``metrics``
(Prometheus, ``service.metrics_port``), ``bench`` (``finepos bench service``).
"""
