#!/usr/bin/env bash
# Make sure an OpenCL CPU device exists: install Debian's PoCL when no ICD is registered.
# Debian's pocl-opencl-icd is used because the pip PoCL wheel fails to build kernels on these CPUs
# (docs/15-opencl.md §1). Idempotent: does nothing when an ICD is already registered.
set -euo pipefail
if compgen -G "/etc/OpenCL/vendors/*.icd" > /dev/null && dpkg -s pocl-opencl-icd > /dev/null 2>&1; then
    exit 0
fi
SUDO=""
if [ "$(id -u)" != "0" ]; then SUDO="sudo"; fi
echo "installing Debian's PoCL OpenCL runtime (pocl-opencl-icd)"
$SUDO apt-get update -qq
DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq pocl-opencl-icd ocl-icd-libopencl1 > /dev/null
