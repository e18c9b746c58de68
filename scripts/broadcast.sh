#!/usr/bin/env bash
# Broadcast over nginx (docs/broadcast.md): starts an origin and N edge caches
# as the current user (nginx -p RUN -c FILE; every file nginx writes is under
# RUN), stops them, and signs URLs of private broadcasts.
#
#   scripts/broadcast.sh start --run RUN --root ROOT [--origin-port 8080] [--edges 2]
#                              [--edge-port 8081] [--secret SECRET] [--host 127.0.0.1]
#       ROOT holds one directory per broadcast (holoport-record --live-dir ROOT/NAME);
#       edge i listens on edge-port + i. With --secret the edges serve only signed URLs.
#       --no-origin: start only the edges (of an origin already running on --origin-port).
#   scripts/broadcast.sh stop --run RUN
#   scripts/broadcast.sh sign --name NAME --secret SECRET [--ttl 3600] [--base http://HOST:PORT]
#                              [--expires UNIX_S]
#       prints the signed live.json URL (append its ?md5=…&expires=… to every object).
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
conf_dir="$here/../config/nginx"
die() { echo "broadcast.sh: $*" >&2; exit 2; }

cmd="${1:-}"
[[ -n "$cmd" ]] || die "usage: broadcast.sh start|stop|sign [options] (see the header of this script)"
shift
run="" root="" origin_port=8080 edges=2 edge_port=8081 secret="" host=127.0.0.1
name="" ttl=3600 base="" expires="" no_origin=0
while (($#)); do
  case "$1" in
    --run) run="$2"; shift 2 ;;
    --root) root="$2"; shift 2 ;;
    --origin-port) origin_port="$2"; shift 2 ;;
    --edges) edges="$2"; shift 2 ;;
    --edge-port) edge_port="$2"; shift 2 ;;
    --secret) secret="$2"; shift 2 ;;
    --host) host="$2"; shift 2 ;;
    --name) name="$2"; shift 2 ;;
    --ttl) ttl="$2"; shift 2 ;;
    --base) base="$2"; shift 2 ;;
    --expires) expires="$2"; shift 2 ;;
    --no-origin) no_origin=1; shift ;;
    *) die "unknown option '$1'" ;;
  esac
done

check_secret() {
  [[ "$secret" =~ ^[A-Za-z0-9._~+=-]{8,256}$ ]] ||
    die "--secret must be 8..256 characters of A-Z a-z 0-9 . _ ~ + = - (got ${#secret} characters)"
}

# sign NAME EXPIRES → base64url(md5(EXPIRES + "/NAME/" + " " + SECRET)) without padding
signature() {
  printf '%s' "$2/$1/ $secret" | openssl md5 -binary | openssl base64 | tr '+/' '-_' | tr -d '=\n'
}

fill() {  # fill TEMPLATE OUT RUN LISTEN [ORIGIN]
  local user_line=""
  # A master started as root hands the workers to "nobody", who cannot write
  # RUN; keep them as the invoking user.
  if [[ $(id -u) -eq 0 ]]; then user_line="user root;"; fi
  local secure=""
  if [[ -n "$secret" ]]; then
    secure="      secure_link \$arg_md5,\$arg_expires;
      secure_link_md5 \"\$secure_link_expires/\$bcast/ $secret\";
      if (\$secure_link = \"\") { return 403; }
      if (\$secure_link = \"0\") { return 403; }"
  fi
  mkdir -p "$3/tmp" "$3/cache"
  local tmp
  tmp="$(mktemp)"
  sed -e "s#@RUN@#$3#g" -e "s#@LISTEN@#$4#g" -e "s#@ORIGIN@#${5:-}#g" -e "s#@ROOT@#$root#g" \
      -e "s#@USER_LINE@#$user_line#g" "$1" > "$tmp"
  awk -v block="$secure" '{ if ($0 == "@SECURE@") print block; else print }' "$tmp" > "$2"
  rm -f "$tmp"
}

start_one() {  # start_one RUN CONF
  nginx -p "$1" -e "$1/error.log" -c "$2" -t -q 2> "$1/configtest.log" ||
    { cat "$1/configtest.log" >&2; die "nginx refused $2"; }
  nginx -p "$1" -e "$1/error.log" -c "$2"
}

case "$cmd" in
  start)
    command -v nginx > /dev/null || die "nginx is not installed (scripts/setup.sh installs nginx-light)"
    [[ -n "$run" && -n "$root" ]] || die "start needs --run RUN and --root ROOT"
    [[ "$edges" =~ ^[0-9]+$ ]] && ((edges >= 0 && edges <= 64)) || die "--edges must be 0..64"
    [[ -z "$secret" ]] || check_secret
    mkdir -p "$run" "$root"
    run="$(cd "$run" && pwd)"
    root="$(cd "$root" && pwd)"
    if ((!no_origin)); then
      mkdir -p "$run/origin"
      fill "$conf_dir/origin.conf.in" "$run/origin/nginx.conf" "$run/origin" "$host:$origin_port"
      start_one "$run/origin" "$run/origin/nginx.conf"
      echo "origin  http://$host:$origin_port/  (root $root, logs $run/origin/)"
    fi
    for ((i = 0; i < edges; ++i)); do
      d="$run/edge$i"
      mkdir -p "$d"
      fill "$conf_dir/edge.conf.in" "$d/nginx.conf" "$d" "$host:$((edge_port + i))" "$host:$origin_port"
      start_one "$d" "$d/nginx.conf"
      echo "edge$i   http://$host:$((edge_port + i))/$([[ -n "$secret" ]] && echo '  (signed URLs only)')"
    done
    ;;
  stop)
    [[ -n "$run" ]] || die "stop needs --run RUN"
    for d in "$run"/origin "$run"/edge*; do
      [[ -f "$d/nginx.pid" ]] || continue
      nginx -p "$d" -e "$d/error.log" -c "$d/nginx.conf" -s quit 2> /dev/null || true
    done
    # Wait (≤ 5 s) for the masters to leave.
    for _ in $(seq 50); do
      alive=0
      for d in "$run"/origin "$run"/edge*; do
        # (a master removes its pid file as it leaves: read it once, quietly)
        pid="$(cat "$d/nginx.pid" 2> /dev/null || true)"
        [[ -n "$pid" ]] && kill -0 "$pid" 2> /dev/null && alive=1
      done
      ((alive)) || break
      sleep 0.1
    done
    ;;
  sign)
    [[ "$name" =~ ^[A-Za-z0-9_-]+$ ]] || die "sign needs --name NAME (A-Z a-z 0-9 _ -)"
    check_secret
    [[ -n "$expires" ]] || expires=$(($(date +%s) + ttl))
    sig="$(signature "$name" "$expires")"
    echo "${base}/$name/live.json?md5=$sig&expires=$expires"
    ;;
  *) die "unknown command '$cmd' (start, stop or sign)" ;;
esac
