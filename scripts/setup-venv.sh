#!/usr/bin/env bash
# `make setup`: create VENV and install the pinned versions of constraints.txt into it, saying
# each step on stderr as it happens (the installers themselves stay quiet).
#
#   scripts/setup-venv.sh PYTHON VENV UV_VERSION
#
# uv installs the packages: about 5 s from its own cache, 15 s from an empty one (pip takes
# one to two minutes here, most of it byte-compiling every module of every package up front,
# and its HTTP cache stays empty behind a proxy that says no-store). uv itself is installed
# once per machine, by PYTHON's pip, into the per-user cache folder (BREVE_CACHE_DIR, else
# $XDG_CACHE_HOME/breve-pipeline, else ~/.cache/breve-pipeline; see pipeline/paths.py), so a
# new clone creates its venv without pip's bootstrap (0.2 s instead of 6 s here) and has uv
# the way it has the wheels. The venv still gets what `python -m venv` would bootstrap into it
# (pip, and setuptools before Python 3.12, at ensurepip's versions), installed by uv. Where uv cannot be had, `python -m venv` and pip do
# it all as before. Nothing is byte-compiled up front: each module is compiled the first time
# a command imports it (the Makefile unexports PYTHONDONTWRITEBYTECODE).
set -uo pipefail
python=${1:?PYTHON} venv=${2:?VENV} uv_version=${3:?UV_VERSION}
say() { echo "setup: $*" >&2; }
t0=$(date +%s)
# The per-user cache folder, as pipeline/paths.py finds it; none without a home: no uv then.
cache=${BREVE_CACHE_DIR:-${XDG_CACHE_HOME:-${HOME:+$HOME/.cache}}}
[ -z "${BREVE_CACHE_DIR:-}" ] && [ -n "$cache" ] && cache=$cache/breve-pipeline
[ -n "${HOME:-}" ] && cache=${cache/#\~/$HOME}
uv_dir=$cache/uv-$uv_version
uv=$uv_dir/bin/uv

with_pip() {  # the venv and the packages by pip alone: where uv cannot be had or fails
    say "$1; creating $venv with pip ($("$python" --version 2>&1))"
    "$python" -m venv "$venv" || exit $?
    say "installing the pinned packages of constraints.txt into $venv (pip, one to two" \
        "minutes; once)"
    "$venv/bin/python" -m pip install --quiet --no-compile -c constraints.txt -e ".[dev,slurm]" \
        || exit $?
}

if [ -n "$cache" ] && ! "$uv" --version >/dev/null 2>&1; then
    say "installing uv $uv_version, the installer, into $uv_dir (pip; once per machine)"
    # Into a temporary folder beside it, then renamed: a cut-short install is never taken
    # for a whole one, and of two set-ups at once the second to finish keeps the first's.
    if mkdir -p "$cache" && tmp=$(mktemp -d "$cache/.uv-$uv_version.XXXXXX"); then
        if PIP_ROOT_USER_ACTION=ignore "$python" -m pip install --quiet --no-compile \
                --disable-pip-version-check \
                --target "$tmp" "uv==$uv_version" && "$tmp/bin/uv" --version >/dev/null 2>&1; then
            "$uv" --version >/dev/null 2>&1 || rm -rf "$uv_dir"  # a damaged copy
            [ -e "$uv_dir" ] || mv "$tmp" "$uv_dir"
        fi
        rm -rf "$tmp"
    fi
fi

if [ -n "$cache" ] && "$uv" --version >/dev/null 2>&1; then
    say "creating $venv ($("$python" --version 2>&1), $("$uv" --version))"
    "$python" -m venv --without-pip "$venv" || exit $?
    # What `python -m venv` would bootstrap (pip, and setuptools before Python 3.12), pinned
    # to the versions this Python bundles.
    bootstrap=$("$venv/bin/python" -c "import ensurepip as e; p = getattr(e, '_get_packages', \
None); print(' '.join(f'{n}=={v.version}' for n, v in p().items()) if p else 'pip==' + e.version())") \
        || exit $?
    say "installing the pinned packages of constraints.txt into $venv (uv: about 5 s from" \
        "its cache, 15 s without; once)"
    # shellcheck disable=SC2086  # $bootstrap: one argument per package
    "$uv" pip install --quiet --python "$venv/bin/python" -c constraints.txt \
        -e ".[dev,slurm]" $bootstrap || with_pip "uv failed (exit $?)"
else
    with_pip "no uv"
fi
say "done in $(( $(date +%s) - t0 )) s"
