#!/usr/bin/env bash
# A local stand-in for python:3.11-slim, built from Debian packages, for machines that reach a
# Debian mirror but no container registry. Then build the project on it:
#   sudo deploy/base-image.sh                       # -> localhost/beyond-self-base:bookworm
#   podman build --build-arg BASE=localhost/beyond-self-base:bookworm -t beyond-self:latest .
# Like python:3.11-slim it has `python` and `pip` first on PATH and pip installs system-wide
# (here into a venv at /opt/python: Debian's own interpreter refuses pip installs, PEP 668).
# espeak-ng is included (the speech service's synthesizer). Needs root and debootstrap.
#
# Usage: deploy/base-image.sh [--engine podman|docker] [--tag TAG] [--mirror URL] [--force]
# Does nothing when TAG exists already, unless --force.
set -euo pipefail

engine=${ENGINE:-podman}
tag=localhost/beyond-self-base:bookworm
mirror=http://deb.debian.org/debian
force=0
while [ $# -gt 0 ]; do
  case "$1" in
    --engine) engine=$2; shift 2 ;;
    --tag) tag=$2; shift 2 ;;
    --mirror) mirror=$2; shift 2 ;;
    --force) force=1; shift ;;
    *) echo "base-image.sh: unknown argument $1; valid: --engine E, --tag T, --mirror URL, --force" >&2
       exit 2 ;;
  esac
done

if [ "$force" = 0 ] && "$engine" image inspect "$tag" >/dev/null 2>&1; then
  echo "base-image.sh: $tag exists (--force rebuilds it)"
  exit 0
fi
if [ "$(id -u)" != 0 ]; then
  echo "base-image.sh: debootstrap needs root" >&2
  exit 2
fi
command -v debootstrap >/dev/null || { echo "base-image.sh: install debootstrap first" >&2; exit 2; }

root=$(mktemp -d /var/tmp/beyond-base.XXXXXX)
chmod 755 "$root"  # it becomes the image's /: mktemp made it 0700, closed to non-root users
trap 'rm -rf "$root"' EXIT
debootstrap --variant=minbase bookworm "$root" "$mirror"
# apt inside, not debootstrap --include: debootstrap's resolver misses python3.11-venv's deps
chroot "$root" apt-get update -qq
chroot "$root" env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends \
  python3.11 python3.11-venv espeak-ng ca-certificates >/dev/null
chroot "$root" python3.11 -m venv /opt/python
# what a slim image leaves out: package caches and lists, documentation, man pages
rm -rf "$root"/var/cache/apt/archives/*.deb "$root"/var/cache/apt/*.bin "$root"/var/lib/apt/lists/* \
  "$root"/usr/share/doc/* "$root"/usr/share/man/* "$root"/usr/share/info/*

tar -C "$root" --numeric-owner -c . | "$engine" import \
  --change 'ENV PATH=/opt/python/bin:/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin' \
  --change 'ENV LANG=C.UTF-8' \
  --change 'CMD ["python3"]' \
  - "$tag"
echo "base-image.sh: imported $tag"
