#!/usr/bin/env bash
# Two PCs on one machine: cell.launch puts model_matching on a "second PC" at 127.0.0.2, reached
# by ssh as another user, so roslaunch takes the same path as for a real second PC (paramiko ssh,
# known_hosts, the env-loader, a remote roslaunch child under the one master). Checks that the
# node runs there (its process descends from that sshd) and serves its service across.
# Needs root: it adds a login (uid 0 alias, so the remote side can read this build wherever the
# checkout lies) and runs an sshd on 127.0.0.2; both are removed at the end.
# Usage: two_pc.sh <build folder> <work folder>
set -uo pipefail
BUILD=$(cd "$1" && pwd)
WORK=$2
ROOT=$(cd "$(dirname "$0")/.." && pwd)
if [ "$(id -u)" != 0 ]; then
  echo "SKIP: needs root (adds a login and runs sshd on 127.0.0.2)"
  exit 77
fi
for tool in /usr/sbin/sshd /usr/bin/ssh-keygen; do
  [ -x "$tool" ] || { echo "FAIL: $tool missing (scripts/install-deps.sh installs openssh-server)"; exit 1; }
done
/usr/bin/python3 -c 'import paramiko' 2>/dev/null || { echo "FAIL: python3-paramiko missing (roslaunch's ssh)"; exit 1; }
source "$ROOT/scripts/ros-env.sh" "$BUILD"
rm -rf "$WORK" && mkdir -p "$WORK/home/.ssh" "$WORK/pc2home" && chmod 700 "$WORK/home/.ssh"
PC2_USER=cellsight_pc2
PC2=127.0.0.2
PORT=$(free_port)
pids=()
cleanup() {
  trap - EXIT INT TERM
  for p in "${pids[@]}"; do kill -INT "$p" 2>/dev/null; done
  for _ in $(seq 50); do
    alive=0
    for p in "${pids[@]}"; do kill -0 "$p" 2>/dev/null && alive=1; done
    [ $alive = 0 ] && break
    sleep 0.1
  done
  for p in "${pids[@]}"; do kill -9 "$p" 2>/dev/null; done
  # whatever the second PC still runs (its roslaunch child, model_matching) and its sshd
  pkill -9 -f "$WORK/pc2home" 2>/dev/null
  pkill -9 -f "sshd -f $WORK/sshd_config" 2>/dev/null
  userdel -f "$PC2_USER" 2>/dev/null
  rm -rf "$WORK/home/.ssh" "$WORK/authorized_keys" "$WORK/host_key" "$WORK/host_key.pub"
  return 0
}
trap cleanup EXIT
trap 'cleanup; exit 1' INT TERM
userdel -f "$PC2_USER" 2>/dev/null
useradd -o -u 0 -g 0 -M -p "*" -d "$WORK/pc2home" -s /bin/bash "$PC2_USER" 2>/dev/null || { echo "FAIL: useradd"; exit 1; }
ssh-keygen -q -t ed25519 -N "" -f "$WORK/host_key" && ssh-keygen -q -t ed25519 -N "" -f "$WORK/home/.ssh/id_ed25519"
cp "$WORK/home/.ssh/id_ed25519.pub" "$WORK/authorized_keys"
mkdir -p /run/sshd
cat >"$WORK/sshd_config" <<CFG
ListenAddress $PC2
Port $PORT
HostKey $WORK/host_key
AuthorizedKeysFile $WORK/authorized_keys
PermitRootLogin prohibit-password
PasswordAuthentication no
KbdInteractiveAuthentication no
UsePAM no
StrictModes no
PidFile $WORK/sshd.pid
AllowUsers $PC2_USER
CFG
/usr/sbin/sshd -f "$WORK/sshd_config" -D -E "$WORK/sshd.log" &
pids+=($!)
# roslaunch checks the bare address, paramiko then [address]:port
{ echo "$PC2 $(cut -d' ' -f1,2 "$WORK/host_key.pub")"; echo "[$PC2]:$PORT $(cut -d' ' -f1,2 "$WORK/host_key.pub")"; } \
  >"$WORK/home/.ssh/known_hosts"
printf 'Host %s\n  IdentityFile %s\n' "$PC2" "$WORK/home/.ssh/id_ed25519" >"$WORK/home/.ssh/config"
# the second PC finds this build through CELLSIGHT_BUILD, then the project's env-loader. Its nodes
# advertise 127.0.0.1: roscpp binds its TCPROS server to 127.0.0.1 alone whenever ROS_IP is a
# loopback address, so 127.0.0.2 would be advertised but not served (a real PC has its own address)
printf '#!/usr/bin/env bash\nexport CELLSIGHT_BUILD=%s ROS_HOME=%s/pc2home/ros ROS_IP=127.0.0.1\nexec %s/scripts/env-loader.sh "$@"\n' \
  "$BUILD" "$WORK" "$ROOT" >"$WORK/env-loader.sh"
chmod +x "$WORK/env-loader.sh"
for _ in $(seq 50); do (exec 3<>"/dev/tcp/$PC2/$PORT") 2>/dev/null && break; sleep 0.1; done

HOME="$WORK/home" roslaunch -p "${ROS_MASTER_URI##*:}" cellsight cell.launch trigger:=false publish_calibration:=false \
  matching_address:=$PC2 matching_user:=$PC2_USER matching_ssh_port:=$PORT env_loader:="$WORK/env-loader.sh" \
  >"$WORK/launch.log" 2>&1 &
pids+=($!)
ok=0
deadline=$(( $(date +%s) + 60 ))  # well inside ctest's 180 s: the cleanup must run
while [ "$(date +%s)" -lt "$deadline" ]; do
  if rosservice list 2>/dev/null | grep -q "^/model_matching/locate_objects$"; then ok=1; break; fi
  grep -qE "RLException|failed to launch|has died" "$WORK/launch.log" && break
  sleep 0.5
done
fail() { echo "FAIL: $*"; echo "--- launch.log"; tail -20 "$WORK/launch.log"; echo "--- sshd.log"; tail -5 "$WORK/sshd.log"; exit 1; }
[ $ok = 1 ] || fail "model_matching did not come up on the second PC"
grep -q "remote\[$PC2-0\]" "$WORK/launch.log" || fail "roslaunch did not start a remote child on $PC2"
pid=$(pgrep -f "model_matching __name:=model_matching.*$WORK/pc2home" | head -1)
[ -n "$pid" ] || fail "no model_matching process"
chain=""
p=$pid
while [ "$p" -gt 1 ]; do chain="$chain $(ps -o comm= -p "$p")"; p=$(ps -o ppid= -p "$p" | tr -d ' '); done
echo "model_matching (pid $pid) runs under:$chain"
echo "$chain" | grep -q sshd || fail "model_matching is not a child of the second PC's sshd"
answer=$(rosservice call /model_matching/locate_objects "models: []" 2>&1)
echo "$answer" | grep -q "status: 1" || fail "locate_objects across the two PCs answered: $answer"
echo "locate_objects answered from the second PC: $(echo "$answer" | grep message)"
echo "1 passed, 0 failed"
