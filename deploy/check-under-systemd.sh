#!/bin/bash
# Run deploy/finepos.service under a live systemd: a throwaway Debian container booted with
# systemd-nspawn (systemd as its PID 1), all local, removed at the end.
#
# Usage (as root, on Debian; the checkout's .venv must be set up: make setup):
#   sudo deploy/check-under-systemd.sh [--keep] [--config FILE]
# --keep: leave the container's root file system in place (the next run reuses it) instead of
# removing it; the container itself is always shut down. --config: the service config to
# install (default deploy/finepos.yaml; its devices must be the simulated cell for the jobs).
#
# The unit and the config are installed unchanged, as docs/service.md says
# (finepos user in dialout, /etc/finepos/finepos.yaml, unit in /etc/systemd/system).
# /opt/finepos/.venv is a small venv over this checkout's .venv (bound read-only), so ExecStart
# is the unit's own. Steps, each printed PASS or FAIL:
#   verify    systemd-analyze verify of the installed unit
#   start     systemctl start: active (running) once READY=1 came, STATUS= shows the state
#   status    systemctl status, and `finepos ctl status` as a member of the finepos group
#   reload    systemctl reload (SIGHUP): same PID, STATUS= says reloaded; a config with an
#             unknown key is refused and the service keeps running
#   jobs      teach --auto, acquire nn1 and nn2, train, position as that group member, under
#             the unit's sandboxing: each done, no permission error in the journal
#   stop      systemctl stop: inactive, exit status 0, no restart
#   exit-2    a config that cannot be loaded: the start fails with status 2, no restart
#   crash     SIGKILL of the main process: restarted (NRestarts + 1)
#   watchdog  the VAL emulator (finepos sim val-emulator --tcp) swapped for one that echoes but
#             never answers, arm.exchange_timeout_s 120 s: the control loop hangs in the arm's
#             reconnection, the pings stop, systemd kills it after WatchdogSec (30 s) and
#             restarts it; with the emulator back the service reconnects and `reset` makes it
#             idle
# Notes (not PASS/FAIL) say whether the cgroup-based settings (DevicePolicy/DeviceAllow,
# IPAddressDeny/Allow) are enforced on this host: they need the devices controller / cgroup v2.
# Exit status: 0 when every step passed, 1 when one failed, 2 when the check could not run.
set -u

MACHINE=finepos-check
ROOT=/var/lib/machines/$MACHINE
REPO=$(cd "$(dirname "$0")/.." && pwd)
KEEP=0
CONFIG=$REPO/deploy/finepos.yaml
while [ $# -gt 0 ]; do
    case "$1" in
        --keep) KEEP=1; shift;;
        --config) [ $# -ge 2 ] || { echo "--config needs a FILE" >&2; exit 2; }
                  CONFIG=$(realpath "$2"); shift 2;;
        *) echo "usage: $0 [--keep] [--config FILE]" >&2; exit 2;;
    esac
done
WORK=""
NSPAWN_PID=""
LEADER=""
FAILED=0

die() { echo "check-under-systemd: $*" >&2; exit 2; }
pass() { echo "PASS $1: $2"; }
fail() { echo "FAIL $1: $2"; FAILED=1; }
note() { echo "NOTE $1"; }
ct() { nsenter -t "$LEADER" -a "$@"; }
prop() { ct systemctl show -p "$2" --value "$1"; }

cleanup() {
    if [ -n "$LEADER" ] && [ -d "/proc/$LEADER" ]; then
        ct systemctl poweroff >/dev/null 2>&1 || true
    fi
    if [ -n "$NSPAWN_PID" ]; then
        for _ in $(seq 60); do [ -d "/proc/$NSPAWN_PID" ] || break; sleep 0.5; done
        [ -d "/proc/$NSPAWN_PID" ] && kill "$NSPAWN_PID" 2>/dev/null
        wait "$NSPAWN_PID" 2>/dev/null
    fi
    if [ "$KEEP" = 0 ] && [ -d "$ROOT" ]; then
        rm -rf --one-file-system "$ROOT"
    fi
    [ -n "$WORK" ] && rm -rf "$WORK"
}

# -- prerequisites --------------------------------------------------------------------------
[ "$(id -u)" = 0 ] || die "run as root"
[ -f "$REPO/.venv/pyvenv.cfg" ] || die "no $REPO/.venv (run make setup first)"
case "$REPO" in /home/*|/root/*|/run/user/*)
    die "the checkout $REPO is under a folder ProtectHome=yes hides; copy it to /opt or /srv";;
esac
for tool in systemd-nspawn debootstrap; do
    command -v $tool >/dev/null || { DEBIAN_FRONTEND=noninteractive apt-get install -y -qq \
        systemd-container debootstrap >/dev/null || die "cannot install $tool"; break; }
done
PYHOME=$(sed -n 's/^home *= *//p' "$REPO/.venv/pyvenv.cfg")   # .../bin of the base Python
PYEXE=$(readlink -f "$REPO/.venv/bin/python3")
PYVER=$(sed -n 's/^version *= *\([0-9]*\.[0-9]*\).*/\1/p' "$REPO/.venv/pyvenv.cfg")
[ -n "$PYHOME" ] && [ -x "$PYEXE" ] && [ -n "$PYVER" ] || die "cannot read $REPO/.venv/pyvenv.cfg"
err=$("$REPO/.venv/bin/python3" -c 'import sys; from controller.config import load_config
load_config(sys.argv[1])' "$CONFIG" 2>&1) || die "$CONFIG does not load: $(echo "$err" | tail -1)"
SUITE=$(. /etc/os-release && echo "${VERSION_CODENAME:-bookworm}")
MIRROR=${DEBIAN_MIRROR:-http://deb.debian.org/debian}

# A leftover container of an interrupted run.
if pgrep -f "systemd-nspawn .*--machine=$MACHINE" >/dev/null; then
    die "a container $MACHINE is still running (an earlier run?): stop it first"
fi
WORK=$(mktemp -d /tmp/finepos-check.XXXXXX)
trap cleanup EXIT
trap 'exit 1' INT TERM

# -- the container's root file system ---------------------------------------------------------
BINDS=(--bind-ro="$REPO")
if [ -f "$ROOT/etc/finepos-check.done" ]; then
    echo "reusing $ROOT"
else
    rm -rf --one-file-system "$ROOT"
    echo "debootstrap $SUITE into $ROOT (a few minutes)"
    debootstrap --variant=minbase --include=systemd,systemd-sysv,dbus,procps,libgl1,libglib2.0-0 \
        "$SUITE" "$ROOT" "$MIRROR" > "$WORK/debootstrap.log" 2>&1 \
        || { tail -5 "$WORK/debootstrap.log"; die "debootstrap failed"; }
    # Shared libraries a python.org / pyenv build links against that minbase lacks.
    chroot "$ROOT" apt-get install -y -qq --no-install-recommends libsqlite3-0 libtirpc3 \
        libnsl2 libreadline8 libpng16-16 libfreetype6 libfontconfig1 libbrotli1 \
        >"$WORK/apt.log" 2>&1 || { tail -5 "$WORK/apt.log"; die "apt-get in the container failed"; }
    case "$PYHOME" in /usr/*)   # a distribution Python: the same one inside
        chroot "$ROOT" apt-get install -y -qq --no-install-recommends "python$PYVER" \
            >>"$WORK/apt.log" 2>&1 || die "no python$PYVER for $SUITE";;
    esac
    chroot "$ROOT" apt-get clean
    echo "$MACHINE" > "$ROOT/etc/hostname"
    touch "$ROOT/etc/finepos-check.done"
fi
case "$PYHOME" in
    /usr/*) CT_PYEXE=$PYEXE; CT_PYHOME=$PYHOME;;
    *)  # bound read-only where ProtectHome= does not hide it; its RUNPATH via ld.so.conf
        BASE=$(dirname "$PYHOME")
        mkdir -p "$ROOT/opt/python-host"
        BINDS+=(--bind-ro="$BASE:/opt/python-host")
        echo /opt/python-host/lib > "$ROOT/etc/ld.so.conf.d/python-host.conf"
        CT_PYEXE=/opt/python-host/${PYEXE#"$BASE"/}
        CT_PYHOME=/opt/python-host/bin;;
esac

# -- boot it -----------------------------------------------------------------------------------
NSPAWN=(systemd-nspawn -b -D "$ROOT" --machine="$MACHINE" --private-network
        --console=passive "${BINDS[@]}")
# Without systemd on the host there is no machined/scope to register with.
[ -d /run/systemd/system ] || NSPAWN+=(--register=no --keep-unit)
"${NSPAWN[@]}" > "$WORK/nspawn.log" 2>&1 &
NSPAWN_PID=$!
for _ in $(seq 60); do
    LEADER=$(pgrep -P "$NSPAWN_PID" -x systemd | head -1)
    [ -n "$LEADER" ] && break
    [ -d "/proc/$NSPAWN_PID" ] || break
    sleep 0.5
done
[ -n "$LEADER" ] || { cat "$WORK/nspawn.log"; die "systemd-nspawn did not boot systemd"; }
STATE=$(ct timeout 90 systemctl is-system-running --wait 2>/dev/null)
case "$STATE" in running|degraded) echo "container booted: systemd $(ct systemctl --version \
    | sed -n '1s/systemd \([0-9]*\).*/\1/p') as PID 1, system $STATE";;
    *) cat "$WORK/nspawn.log"; die "container did not boot (state: ${STATE:-none})";;
esac

# -- install as docs/service.md says ----------------------------------------------------------
cp "$CONFIG" "/proc/$LEADER/root/run/finepos-check.yaml" || die "cannot copy $CONFIG"
SITE=lib/python$PYVER/site-packages
ct sh -ec "
ldconfig
id finepos >/dev/null 2>&1 || useradd --system --user-group --groups dialout \
    --home-dir /var/lib/finepos --shell /usr/sbin/nologin finepos
id alice >/dev/null 2>&1 || useradd --no-create-home --gid users --groups finepos alice
V=/opt/finepos/.venv
mkdir -p \$V/bin \$V/$SITE
printf 'home = %s\ninclude-system-site-packages = false\nversion = %s\n' '$CT_PYHOME' '$PYVER' \
    > \$V/pyvenv.cfg
ln -sfn '$CT_PYEXE' \$V/bin/python3
ln -sfn python3 \$V/bin/python
echo \"import site; site.addsitedir('$REPO/.venv/$SITE')\" > \$V/$SITE/finepos-checkout.pth
sed '1s|.*|#!/opt/finepos/.venv/bin/python3|' '$REPO/.venv/bin/finepos' > \$V/bin/finepos
chmod 755 \$V/bin/finepos
install -d /etc/finepos
install -m 0640 -g finepos /run/finepos-check.yaml /etc/finepos/finepos.yaml
cp '$REPO/deploy/finepos.service' /etc/systemd/system/finepos.service
systemctl daemon-reload
" || die "installing into the container failed"
FP=/opt/finepos/.venv/bin/finepos

wait_for() {  # wait_for SECONDS COMMAND...: until COMMAND succeeds
    local until=$((SECONDS + $1)); shift
    while [ $SECONDS -lt "$until" ]; do "$@" && return 0; sleep 0.5; done
    return 1
}
status_has() { prop finepos StatusText | grep -q -- "$1"; }
restarts_are() { [ "$(prop finepos NRestarts)" = "$1" ]; }
journal() { ct journalctl -u finepos --since "@$SINCE" --no-pager -o cat 2>/dev/null; }
journal_has() { journal | grep -q -- "$1"; }
SINCE=$(ct date +%s)
ctl_state() { ct runuser -u alice -- $FP ctl status 2>/dev/null \
    | sed -n 's/^  "state": "\(.*\)",/\1/p'; }

# verify
if out=$(ct systemd-analyze verify /etc/systemd/system/finepos.service 2>&1) \
        && [ -z "$out" ]; then
    pass verify "systemd-analyze verify: no findings"
else
    fail verify "$out"
fi

# start
t0=$SECONDS
if ct systemctl start finepos && [ "$(prop finepos SubState)" = running ] \
        && status_has "^idle"; then
    pass start "active (running) after $((SECONDS - t0)) s, Status: $(prop finepos StatusText)"
else
    fail start "$(ct systemctl status finepos --no-pager -l 2>&1 | tail -15)"
fi
PID=$(prop finepos MainPID)

# status
if ct systemctl status finepos --no-pager >"$WORK/status.txt" 2>&1 \
        && [ "$(ctl_state)" = idle ]; then
    pass status "systemctl status exit 0 (PID $PID, watchdog $(prop finepos WatchdogUSec)); \
finepos ctl status as alice (group finepos): idle"
else
    fail status "$(tail -5 "$WORK/status.txt"); ctl state: '$(ctl_state)'"
fi

# reload, then a refused reload
SINCE=$(ct date +%s)
ok=1
ct systemctl reload finepos || ok=0
wait_for 10 status_has "reloaded" || ok=0
[ "$(prop finepos MainPID)" = "$PID" ] || ok=0
ct cp -p /etc/finepos/finepos.yaml /etc/finepos/finepos.yaml.good
ct sh -c 'printf "\nbogus_section: 1\n" >> /etc/finepos/finepos.yaml'
ct systemctl reload finepos || ok=0
wait_for 10 status_has "refused" || ok=0
[ "$(prop finepos MainPID)" = "$PID" ] && [ "$(prop finepos SubState)" = running ] || ok=0
ct mv /etc/finepos/finepos.yaml.good /etc/finepos/finepos.yaml
if [ $ok = 1 ]; then
    pass reload "SIGHUP reloaded in PID $PID; a bad key refused: $(prop finepos StatusText \
        | cut -c1-140)"
else
    fail reload "Status: $(prop finepos StatusText); MainPID $(prop finepos MainPID) (was $PID)"
fi

# jobs under the sandbox (seccomp filter, read-only system, the unit's directories)
ok=1; took=""
for job in "teach --auto" "acquire --set nn1" "acquire --set nn2" "train" \
        "position --offset 12,-8,20"; do
    t0=$SECONDS
    ct runuser -u alice -- $FP ctl $job > "$WORK/job.json" 2>&1
    outcome=$(sed -n 's/^    "outcome": "\(.*\)",/\1/p' "$WORK/job.json")
    took="$took ${job%% *} $((SECONDS - t0)) s,"
    [ "$outcome" = "done" ] || { ok=0; took="$took (${outcome:-no answer}: \
$(grep -m1 '"reason"' "$WORK/job.json"))"; break; }
done
denied=$(journal | grep -c -i -e "operation not permitted" -e "permission denied" \
    -e "read-only file system")
if [ $ok = 1 ] && [ "$denied" = 0 ] && [ "$(prop finepos MainPID)" = "$PID" ]; then
    pass jobs "done as alice through the socket:${took%,}; no permission errors in the journal"
else
    fail jobs "${took%,}; $denied permission lines: $(journal | grep -i -m3 -e "not permitted" \
-e "permission denied" -e "read-only file system")"
fi

# stop
t0=$SECONDS
ct systemctl stop finepos
if [ "$(prop finepos ActiveState)" = inactive ] && [ "$(prop finepos Result)" = success ] \
        && [ "$(prop finepos ExecMainStatus)" = 0 ] && [ "$(prop finepos NRestarts)" = 0 ]; then
    pass stop "inactive after $((SECONDS - t0)) s, exit status 0, NRestarts 0"
else
    fail stop "$(prop finepos ActiveState) $(prop finepos Result) status \
$(prop finepos ExecMainStatus)"
fi

# a config that cannot be loaded: exit 2 is final
SINCE=$(ct date +%s)
ct cp -p /etc/finepos/finepos.yaml /etc/finepos/finepos.yaml.good
ct sh -c 'printf "\nbogus_section: 1\n" >> /etc/finepos/finepos.yaml'
ct systemctl start finepos 2>/dev/null
sleep 4   # twice RestartSec: a restart would have happened
if [ "$(prop finepos ActiveState)" = failed ] && [ "$(prop finepos ExecMainStatus)" = 2 ] \
        && [ "$(prop finepos NRestarts)" = 0 ]; then
    pass exit-2 "start refused, exit status 2, not restarted: $(journal \
        | grep "finepos: error" | tail -1)"
else
    fail exit-2 "$(prop finepos ActiveState) status $(prop finepos ExecMainStatus) NRestarts \
$(prop finepos NRestarts)"
fi
ct mv /etc/finepos/finepos.yaml.good /etc/finepos/finepos.yaml
ct systemctl reset-failed finepos

# crash: restarted
ct systemctl start finepos
PID=$(prop finepos MainPID)
ct systemctl kill -s KILL finepos
if wait_for 30 restarts_are 1 && wait_for 30 status_has "^idle" \
        && [ "$(prop finepos MainPID)" != "$PID" ]; then
    pass crash "SIGKILL of PID $PID: restarted as PID $(prop finepos MainPID), NRestarts 1"
else
    fail crash "$(prop finepos ActiveState) NRestarts $(prop finepos NRestarts)"
fi
ct systemctl stop finepos

# watchdog: a hung control loop
SINCE=$(ct date +%s)
EMU=(systemd-run -q --unit=val-emulator --property=Restart=no "$FP" sim val-emulator --tcp 5001
     --ati-tcp 5002 --mjpeg 5003 --timing ideal --config /etc/finepos/finepos.yaml)
ct /opt/finepos/.venv/bin/python3 - <<'EOF'
import yaml
path = "/etc/finepos/finepos.yaml"
with open(path) as f:
    cfg = yaml.safe_load(f)
cfg["arm"] = {"type": "val", "port": "socket://127.0.0.1:5001", "exchange_timeout_s": 120.0,
              "move_timeout_s": 120.0}
cfg["wrench"] = {"type": "ati", "port": "socket://127.0.0.1:5002"}
cfg["camera"] = {"type": "opencv", "source": "http://127.0.0.1:5003/stream.mjpg"}
with open(path + ".tmp", "w") as f:
    yaml.safe_dump(cfg, f, sort_keys=False)
EOF
ct sh -ec 'chgrp finepos /etc/finepos/finepos.yaml.tmp; chmod 0640 /etc/finepos/finepos.yaml.tmp
          mv /etc/finepos/finepos.yaml /etc/finepos/finepos.yaml.good
          mv /etc/finepos/finepos.yaml.tmp /etc/finepos/finepos.yaml'
ct systemctl reset-failed finepos 2>/dev/null
ct "${EMU[@]}"
ok=1
wait_for 30 ct bash -c 'exec 3<>/dev/tcp/127.0.0.1/5001' 2>/dev/null || ok=0
ct systemctl start finepos || ok=0
PID=$(prop finepos MainPID)
wait_for 20 status_has "^idle" || ok=0
if [ $ok = 1 ]; then
    # The VAL controller still echoes but never answers.
    ct systemctl stop val-emulator
    ct "${EMU[@]}" --reply-delay-s 3600
    t0=$SECONDS
    wait_for 90 journal_has "Watchdog timeout" || ok=0
    waited=$((SECONDS - t0))
    wait_for 10 restarts_are 1 || ok=0
    killed=$(journal | grep -m2 -e "Watchdog timeout" \
        -e "Killing process" | tr '\n' ' ')
    # PYTHONFAULTHANDLER: the stack of each thread at the SIGABRT; the control loop's own.
    journal > "$WORK/watchdog.log"
    hung=$(awk '/^Fatal Python error/ {on = 1} on && /^(Thread|Current thread)/ {block = ""}
                on && /File / {block = block $0 "\n"}
                on && /_control_loop/ {printf "%s", block; exit}' "$WORK/watchdog.log" \
           | sed -n '1,2p;x;$p' | sed 's/^ *File "[^"]*\/\([^/"]*\)", line \([0-9]*\) in /\1:\2 /' \
           | paste -sd' ')
    [ -n "$hung" ] || ok=0
    # The emulator back: the restarted service reconnects by itself, reset makes it idle.
    ct systemctl stop val-emulator
    ct "${EMU[@]}"
    wait_for 60 journal_has "devices reconnected" || ok=0
    ct $FP ctl reset >/dev/null 2>&1 || ok=0
    [ "$(ctl_state)" = idle ] || ok=0
fi
if [ $ok = 1 ] && [ "$(prop finepos MainPID)" != "$PID" ]; then
    pass watchdog "${waited} s after the swap: $killed; the control loop's stack then (innermost \
first): $hung; \
restarted as PID $(prop finepos MainPID) (NRestarts $(prop finepos NRestarts)), reconnected, \
reset: idle"
else
    fail watchdog "$(journal | tail -8)"
fi
ct systemctl stop finepos val-emulator 2>/dev/null
ct mv /etc/finepos/finepos.yaml.good /etc/finepos/finepos.yaml

# -- what this host enforces of the cgroup-based sandboxing (notes) --------------------------
if ct systemd-run -q --wait --pipe -p DevicePolicy=strict sh -c 'head -c1 /dev/zero' \
        >/dev/null 2>&1; then
    note "DevicePolicy/DeviceAllow NOT enforced here (a DevicePolicy=strict unit read /dev/zero)"
else
    note "DevicePolicy enforced here (a DevicePolicy=strict unit could not read /dev/zero)"
fi
if ct systemd-run -q --wait --pipe -p IPAddressDeny=any /opt/finepos/.venv/bin/python3 -c '
import socket
server = socket.create_server(("127.0.0.1", 0))
socket.create_connection(server.getsockname(), 2)
' >/dev/null 2>&1; then
    note "IPAddressDeny/IPAddressAllow NOT enforced here (an IPAddressDeny=any unit connected)"
else
    note "IPAddressDeny enforced here (an IPAddressDeny=any unit could not connect to loopback)"
fi

[ $FAILED = 0 ] && echo "ALL PASS" || echo "SOME FAILED"
exit $FAILED
