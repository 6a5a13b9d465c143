#!/usr/bin/env bash
# A real single-node Slurm cluster on loopback (munge + slurmctld + slurmd, from Debian's
# slurm-wlm and munge, installed by scripts/setup) runs a tiny avp bench through
# scripts/slurm/submit-bench as two array tasks and a dependent merge; the merged summary must be
# the one `avp bench` writes on this machine, byte for byte (docs/cluster.md). Everything is
# started here, in a temporary folder, and stopped on exit. Run by ctest (slurm_bench).
#   tests/slurm_bench_test.sh AVP_BINARY SOURCE_DIR
set -euo pipefail
avp=$(realpath "$1")
src=$(realpath "$2")
for tool in munged munge slurmctld slurmd sbatch squeue scontrol sinfo; do
  if ! command -v "$tool" >/dev/null 2>&1; then
    echo "FAIL: $tool is not installed: run scripts/setup (Debian packages slurm-wlm, munge)" >&2
    exit 1
  fi
done
tmp=$(mktemp -d)
export SLURM_CONF=$tmp/slurm.conf
cleanup() {
  scontrol shutdown >/dev/null 2>&1 || true
  munged --stop --socket="$tmp/munge/munge.socket" >/dev/null 2>&1 || true
  sleep 1
  for f in "$tmp/slurmd.pid" "$tmp/slurmctld.pid" "$tmp/munge/munged.pid"; do
    [ -f "$f" ] && kill "$(cat "$f")" >/dev/null 2>&1 || true
  done
  rm -rf "$tmp"
}
trap cleanup EXIT
fail() {
  echo "FAIL: $*" >&2
  for f in "$tmp"/log/*.log "$tmp"/munge/munged.log "$tmp"/res/logs/*.log; do
    [ -f "$f" ] && { echo "--- $f" >&2; tail -n 20 "$f" >&2; }
  done
  exit 1
}
free_port() {
  python3 -c 'import socket; s = socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])'
}

# munge: its own key, socket and files in the temporary folder.
mkdir -p "$tmp/munge" "$tmp/state" "$tmp/spool" "$tmp/log"
chmod 700 "$tmp/munge"
chmod 755 "$tmp"
head -c 1024 /dev/urandom >"$tmp/munge/munge.key"
chmod 400 "$tmp/munge/munge.key"
munged --force --key-file="$tmp/munge/munge.key" --socket="$tmp/munge/munge.socket" \
  --pid-file="$tmp/munge/munged.pid" --log-file="$tmp/munge/munged.log" \
  --seed-file="$tmp/munge/munged.seed" || fail "munged did not start"

user=$(id -un)
cpus=$(nproc)
cat >"$SLURM_CONF" <<CONF
ClusterName=avptest
SlurmctldHost=localhost(127.0.0.1)
SlurmctldPort=$(free_port)
SlurmdPort=$(free_port)
SlurmUser=$user
SlurmdUser=$user
AuthType=auth/munge
AuthInfo=socket=$tmp/munge/munge.socket
CredType=cred/munge
StateSaveLocation=$tmp/state
SlurmdSpoolDir=$tmp/spool
SlurmctldPidFile=$tmp/slurmctld.pid
SlurmdPidFile=$tmp/slurmd.pid
SlurmctldLogFile=$tmp/log/slurmctld.log
SlurmdLogFile=$tmp/log/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
JobCompType=jobcomp/none
SchedulerType=sched/builtin
SelectType=select/cons_tres
SelectTypeParameters=CR_CPU
ReturnToService=2
MpiDefault=none
NodeName=avpnode NodeHostname=localhost NodeAddr=127.0.0.1 CPUs=$cpus RealMemory=1 State=UNKNOWN
PartitionName=avp Nodes=avpnode Default=YES MaxTime=INFINITE State=UP
CONF
slurmctld -i || fail "slurmctld did not start"
slurmd -N avpnode || fail "slurmd did not start"
for _ in $(seq 1 60); do
  state=$(sinfo -h -N -o '%t' 2>/dev/null || true)
  [ "$state" = "idle" ] && break
  sleep 0.5
done
[ "$state" = "idle" ] || fail "the node is '$state', not idle, after 30 s"

# A tiny bench: 1 scenario x 2 planners x 2 seeds x 2 views, in 2 shards on Slurm.
bench=(--scenarios tomato-single-cluster --planners random,predefined --seeds 2 --views 2)
cd "$tmp"
AVP=$avp "$src/scripts/slurm/submit-bench" --shards 2 --cpus 1 --out "$tmp/res" -- "${bench[@]}" \
  >"$tmp/submit.txt" || fail "submit-bench failed: $(cat "$tmp/submit.txt")"
cat "$tmp/submit.txt"
for _ in $(seq 1 600); do
  [ -z "$(squeue -h 2>/dev/null)" ] && break
  sleep 0.5
done
[ -z "$(squeue -h)" ] || fail "jobs still queued after 300 s: $(squeue)"
for k in 1 2; do
  grep -q "avp bench shard $k/2 on" "$tmp/res/logs/shard-$k.log" ||
    fail "array task $k did not run its shard"
done
grep -q '"state": "complete"' "$tmp/res/merged/avp-state.json" 2>/dev/null ||
  fail "the merge job left no complete bench folder"

"$avp" bench "${bench[@]}" --jobs 2 --out "$tmp/local" >/dev/null 2>&1 || fail "avp bench failed"
for f in summary.csv fruits_by_visibility.csv; do
  cmp "$tmp/local/$f" "$tmp/res/merged/$f" || fail "$f of the Slurm run differs from avp bench's"
done
rows=$(wc -l <"$tmp/res/merged/summary.csv")
[ "$rows" -gt 40 ] || fail "summary.csv has only $rows lines"
echo "OK: 2 Slurm array tasks and the merge gave avp bench's summary.csv ($rows lines) and fruits_by_visibility.csv"
