#!/bin/sh
# hilgate as a systemd service: `sudo make install` and `sudo make uninstall` run this script.
#
#   install     PREFIX (/opt/hilgate): a venv with hilgate installed into it (not editable: it does not
#               use this checkout once installed) and the README with its docs/ pages in share/doc/hilgate;
#               UNITDIR/hilgate.service (/etc/systemd/system), SYSCONFDIR/hilgate/hilgate.env and
#               scene.yaml (from the demo scene; an existing one is never replaced),
#               LOGROTATEDIR/hilgate (/etc/logrotate.d), BINDIR/hilgate (/usr/local/bin) a symbolic
#               link to PREFIX/bin/hilgate for the operator's tools; then, as root on the real system only, the
#               `hilgate` system user and group (the user in dialout) and `systemctl daemon-reload`.
#   uninstall   removes what install wrote, except configuration files changed since (said so; PURGE=1
#               removes them too), stopping and disabling the service first. The hilgate user and
#               group, /var/lib/hilgate and /var/log/hilgate (traces) stay unless PURGE=1.
#
# DESTDIR stages every file under that directory (packaging, tests) and skips the root-only steps
# (accounts, systemctl); the venv's scripts are rewritten to run from PREFIX on the target.
# Configuration files follow dpkg's rule: a file the administrator changed since the last install is
# kept, and the new version is written next to it as FILE.new. The list of what install wrote (with
# checksums) is PREFIX/share/hilgate/installed.
set -eu
umask 022 # the daemon's user must read the venv, whatever umask root has

usage="usage: $0 install|uninstall   (variables: DESTDIR PREFIX SYSCONFDIR UNITDIR LOGROTATEDIR BINDIR PYTHON PIP_ARGS PURGE EXTRAS)"
action=${1:-}
SRC=$(cd "$(dirname "$0")/.." && pwd)
DESTDIR=${DESTDIR:-}
PREFIX=${PREFIX:-/opt/hilgate}
SYSCONFDIR=${SYSCONFDIR:-/etc}
UNITDIR=${UNITDIR:-/etc/systemd/system}
LOGROTATEDIR=${LOGROTATEDIR:-/etc/logrotate.d}
BINDIR=${BINDIR:-/usr/local/bin}
PYTHON=${PYTHON:-python3}
PIP_ARGS=${PIP_ARGS:-}
EXTRAS=${EXTRAS-web} # optional extras for the service's venv (comma-separated; empty: none)
PURGE=${PURGE:-}
ACCOUNT=hilgate  # the unit's User= and Group=

say() { printf 'hilgate: %s\n' "$*"; }
die() { printf 'hilgate: %s\n' "$*" >&2; exit 1; }

case $DESTDIR in
    "" | /*) ;;
    *) DESTDIR=$(pwd)/$DESTDIR ;;
esac
for path in "$PREFIX" "$SYSCONFDIR" "$UNITDIR" "$LOGROTATEDIR" "$BINDIR" "$DESTDIR"; do
    case $path in
        *[!A-Za-z0-9/._+-]*) die "unsupported character in path '$path' (letters, digits and / . _ + - only)" ;;
    esac
done
for path in "$PREFIX" "$SYSCONFDIR" "$UNITDIR" "$LOGROTATEDIR" "$BINDIR"; do
    case $path in
        /?*) ;;
        *) die "'$path' must be an absolute path, not /" ;;
    esac
done
D=${DESTDIR%/}
CONFDIR=$SYSCONFDIR/hilgate
UNIT=$UNITDIR/hilgate.service
ENVFILE=$CONFDIR/hilgate.env
SCENE=$CONFDIR/scene.yaml
LOGROTATE=$LOGROTATEDIR/hilgate
COMMAND=$BINDIR/hilgate
MANIFEST=$PREFIX/share/hilgate/installed
WORK=$(mktemp -d)
trap 'rm -rf "$WORK"' EXIT
trap 'exit 130' INT TERM

# Why the root-only steps are skipped (empty: they run).
system_steps_skipped() {
    if [ -n "$D" ]; then
        echo "DESTDIR is set"
    elif [ "$(id -u)" != 0 ]; then
        echo "not root"
    fi
}
# systemd is running (sd_booted(3)); the variable lets tests take this branch with a stub systemctl
have_systemd() { [ -d "${HILGATE_SYSTEMD_RUN_DIR:-/run/systemd/system}" ] && command -v systemctl >/dev/null 2>&1; }

checksum() { sha256sum <"$1" | cut -d' ' -f1; }

# The repository's file with the default paths replaced by the chosen ones.
render() {
    sed -e "s#/opt/hilgate#$PREFIX#g" -e "s#/etc/hilgate#$CONFDIR#g" "$SRC/$1" >"$WORK/$(basename "$1")"
    echo "$WORK/$(basename "$1")"
}

# The checksum recorded for PATH by the last install ("" when none).
recorded() {
    [ -f "$WORK/old-manifest" ] || return 0
    awk -v p="$1" '$1 == "file" && $3 == p { print $2 }' "$WORK/old-manifest"
}
record() { echo "file $(checksum "$D$1") $1" >>"$WORK/manifest"; }
carry_over() { # keep the last install's entry for PATH (a file install did not rewrite this time)
    sum=$(recorded "$1")
    if [ -n "$sum" ]; then echo "file $sum $1" >>"$WORK/manifest"; fi
}

# A configuration file: written unless the administrator changed the installed one since.
install_config() { # NEW_FILE PATH
    if [ -e "$D$2" ] && ! cmp -s "$1" "$D$2"; then
        sum=$(recorded "$2")
        if [ -z "$sum" ] || [ "$(checksum "$D$2")" != "$sum" ]; then
            install -m 0644 "$1" "$D$2.new"
            say "kept $2 (changed since it was installed); this version is $2.new"
            carry_over "$2"
            return
        fi
    fi
    install -D -m 0644 "$1" "$D$2"
    rm -f "$D$2.new"
    record "$2"
}

do_install() {
    "$PYTHON" -c 'import sys, venv, ensurepip; sys.exit(sys.version_info < (3, 11))' 2>/dev/null ||
        die "needs Python 3.11 or newer with venv as $PYTHON (Debian, Raspberry Pi OS: apt install python3-venv)"
    if [ -z "$D" ] && [ "$(id -u)" != 0 ] && ! [ -w "$(dirname "$PREFIX")" ]; then
        die "installing to $PREFIX and $SYSCONFDIR needs root: sudo make install (or stage with DESTDIR=DIR)"
    fi
    if [ -f "$D$MANIFEST" ]; then cp "$D$MANIFEST" "$WORK/old-manifest"; fi
    : >"$WORK/manifest"

    # the venv, and hilgate built from a copy of the sources: building in place would leave build/ and
    # root-owned files in the checkout
    if [ -e "$D$PREFIX" ] && ! [ -f "$D$PREFIX/pyvenv.cfg" ] && [ -n "$(ls -A "$D$PREFIX")" ]; then
        die "$D$PREFIX exists and is not a venv: will not install into it"
    fi
    where=$PREFIX
    if [ -n "$D" ]; then where="$D$PREFIX (to run as $PREFIX on the target)"; fi
    if ! [ -e "$D$PREFIX/pyvenv.cfg" ]; then
        say "creating the venv $where"
        "$PYTHON" -m venv "$D$PREFIX"
    elif ! "$D$PREFIX/bin/python" -c '' 2>/dev/null; then # its Python is gone (a distribution upgrade)
        say "recreating the venv $where: its Python no longer runs"
        "$PYTHON" -m venv --clear "$D$PREFIX"
    fi
    mkdir "$WORK/src"
    (cd "$SRC" && tar -cf - --exclude=__pycache__ --exclude='*.pyc' \
        pyproject.toml README.md hilgate models drivers scenes $(ls -d LICEN[CS]E* 2>/dev/null || true)) |
        tar -C "$WORK/src" -xf -
    say "installing hilgate and its dependencies into $where"
    compile=--compile
    if [ -n "$D" ]; then compile=--no-compile; fi # compiled below with the target's paths
    # shellcheck disable=SC2086  # PIP_ARGS: several words
    "$D$PREFIX/bin/python" -m pip install --quiet --disable-pip-version-check --no-warn-script-location \
        $compile $PIP_ARGS "$WORK/src${EXTRAS:+[$EXTRAS]}"
    install -D -m 0644 "$SRC/README.md" "$D$PREFIX/share/doc/hilgate/README.md"
    for page in "$SRC"/docs/*.md "$SRC"/docs/figures/*.png; do # the README's links, relative as in the checkout
        install -D -m 0644 "$page" "$D$PREFIX/share/doc/hilgate/${page#"$SRC"/}"
    done
    if [ -n "$D" ]; then # staged: scripts and byte code must name the paths they will have on the target
        grep -rlF -- "$D$PREFIX" "$D$PREFIX/bin" "$D$PREFIX/pyvenv.cfg" 2>/dev/null | while read -r file; do
            if ! [ -L "$file" ]; then sed -i "s#$D$PREFIX#$PREFIX#g" "$file"; fi
        done
        "$D$PREFIX/bin/python" -m compileall -q -f -s "$D" -p / "$D$PREFIX/lib" >/dev/null
    fi

    install -D -m 0644 "$(render systemd/hilgate.service)" "$D$UNIT"
    record "$UNIT"
    install -d -m 0755 "$D$CONFDIR"
    install_config "$(render systemd/hilgate.env)" "$ENVFILE"
    install_config "$(render systemd/hilgate.logrotate)" "$LOGROTATE"
    if [ -e "$D$SCENE" ]; then
        say "kept $SCENE (never replaced)"
        carry_over "$SCENE"
    else
        install -m 0644 "$SRC/scenes/demo.yaml" "$D$SCENE"
        record "$SCENE"
        say "installed the demo scene as $SCENE: edit it for your lab"
    fi

    if [ -L "$D$COMMAND" ] && [ "$(readlink "$D$COMMAND")" = "$PREFIX/bin/hilgate" ]; then
        :
    elif [ -e "$D$COMMAND" ] || [ -L "$D$COMMAND" ]; then
        say "left $COMMAND alone (not ours): the command is $PREFIX/bin/hilgate"
    else
        install -d -m 0755 "$D$BINDIR"
        ln -s "$PREFIX/bin/hilgate" "$D$COMMAND"
    fi

    why=$(system_steps_skipped)
    if [ -n "$why" ]; then
        say "$why: skipping the $ACCOUNT user and group and systemctl; on the target, as root:"
        say "  useradd --system --user-group --groups dialout --home-dir /var/lib/hilgate --no-create-home --shell /usr/sbin/nologin $ACCOUNT"
        say "  systemctl daemon-reload && systemctl enable --now hilgate"
    else
        if ! getent group "$ACCOUNT" >/dev/null; then
            groupadd --system "$ACCOUNT"
            say "created the group $ACCOUNT"
        fi
        if ! getent passwd "$ACCOUNT" >/dev/null; then
            useradd --system --gid "$ACCOUNT" --home-dir /var/lib/hilgate --no-create-home \
                --shell /usr/sbin/nologin --comment "hilgate daemon" "$ACCOUNT"
            say "created the system user $ACCOUNT"
        fi
        if getent group dialout >/dev/null; then usermod -a -G dialout "$ACCOUNT"; fi
        if have_systemd; then
            systemctl daemon-reload
            if systemctl is-active --quiet hilgate; then
                say "hilgate is running the old version: systemctl restart hilgate"
            else
                say "start it now and at boot: systemctl enable --now hilgate"
            fi
        else
            say "systemd is not running here: skipping systemctl daemon-reload"
        fi
    fi
    sort -u "$WORK/manifest" >"$WORK/manifest.sorted"
    install -D -m 0644 "$WORK/manifest.sorted" "$D$MANIFEST"
    say "installed: $PREFIX, $UNIT, $ENVFILE, $SCENE, $LOGROTATE, $COMMAND"
}

# Under DESTDIR: rmdir DIR and its parents while they are empty, up to DESTDIR.
prune_staged() {
    [ -n "$D" ] || return 0
    dir=$D$1
    while [ "$dir" != "$D" ] && { ! [ -e "$dir" ] || rmdir "$dir" 2>/dev/null; }; do
        dir=$(dirname "$dir")
    done
}

do_uninstall() {
    why=$(system_steps_skipped)
    if [ -z "$why" ] && have_systemd && [ -e "$UNIT" ]; then
        systemctl disable --now hilgate || true
    fi
    if [ -f "$D$MANIFEST" ]; then
        cp "$D$MANIFEST" "$WORK/old-manifest"
    else # no record (an interrupted install): remove what is identical to what install would write
        : >"$WORK/old-manifest"
        for pair in "systemd/hilgate.service $UNIT" "systemd/hilgate.env $ENVFILE" \
            "systemd/hilgate.logrotate $LOGROTATE" "scenes/demo.yaml $SCENE"; do
            set -- $pair
            if [ "$1" = scenes/demo.yaml ]; then new=$SRC/$1; else new=$(render "$1"); fi
            echo "file $(checksum "$new") $2" >>"$WORK/old-manifest"
        done
    fi
    kept=""
    while read -r kind sum path; do
        [ "$kind" = file ] || continue
        rm -f "$D$path.new"
        [ -e "$D$path" ] || continue
        if [ "$path" = "$UNIT" ] || [ -n "$PURGE" ] || [ "$(checksum "$D$path")" = "$sum" ]; then
            rm -f "$D$path"
        else
            kept="$kept $path"
            say "kept $path: changed since it was installed (PURGE=1 removes it)"
        fi
    done <"$WORK/old-manifest"
    if [ -L "$D$COMMAND" ] && [ "$(readlink "$D$COMMAND")" = "$PREFIX/bin/hilgate" ]; then
        rm -f "$D$COMMAND"
    fi
    if [ -f "$D$PREFIX/pyvenv.cfg" ]; then
        rm -rf "$D$PREFIX"
    elif [ -e "$D$PREFIX" ]; then
        say "left $PREFIX: not a venv"
    fi
    rmdir "$D$CONFDIR" 2>/dev/null || true # ours: gone when empty
    if [ -n "$PURGE" ]; then rm -rf "$D/var/lib/hilgate" "$D/var/log/hilgate"; fi
    for dir in "$CONFDIR" "$UNITDIR" "$LOGROTATEDIR" "$BINDIR" "$(dirname "$PREFIX")" /var/lib /var/log; do
        prune_staged "$dir"
    done

    if [ -n "$why" ]; then
        say "$why: skipping systemctl and the $ACCOUNT user and group"
    else
        if have_systemd; then systemctl daemon-reload; fi
        if [ -n "$PURGE" ]; then
            if getent passwd "$ACCOUNT" >/dev/null; then
                userdel "$ACCOUNT" && say "removed the user $ACCOUNT"
            fi
            if getent group "$ACCOUNT" >/dev/null; then
                groupdel "$ACCOUNT" && say "removed the group $ACCOUNT"
            fi
        elif getent passwd "$ACCOUNT" >/dev/null; then
            say "kept the $ACCOUNT user and group, /var/lib/hilgate and /var/log/hilgate (traces): PURGE=1 removes them"
        fi
    fi
    say "uninstalled${kept:+; kept (yours):$kept}"
}

case $action in
    install) do_install ;;
    uninstall) do_uninstall ;;
    *) die "$usage" ;;
esac
