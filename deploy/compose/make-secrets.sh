#!/usr/bin/env bash
# The secrets of deploy/compose/compose.secure.yaml, for trying it: a CA and
# certificates (deploy/secure/make-certs.sh, plus the router's own server
# certificate), and a random password per zenoh account. For production use
# your own CA and password store; the file names below are what the compose
# file mounts.
#
#   deploy/compose/make-secrets.sh [DIR]     # default deploy/compose/secrets
#
# Writes into DIR:
#   ca.pem                          the CA every party trusts (ca.key signs; keep it offline)
#   router.pem, router.key          the router's server certificate (names: router, localhost, 127.0.0.1)
#   daemon.pem, daemon.key          the daemons' client certificate (CN daemon)
#   operator.pem, operator.key      an operator's (CN operator: may switch, with the operator account)
#   viewer.pem, viewer.key          an observer's (CN viewer: the view, the Foxglove bridge, watchers)
#   users.txt                       the router's user:password dictionary
#   ACCOUNT.password                one per account: daemon-a daemon-b view foxglove operator observer
#   daemon-a.json5, daemon-b.json5  the daemons' zenoh credentials ([zenoh] config_file)
#
# The files the containers read are left readable by all (0644) inside a
# directory only you can enter (0700): compose bind-mounts each file into
# its container, where uid 10001 must read it, and without swarm it cannot
# change their owner or mode. The rest (ca.key, the operator's key, the
# operator's and observer's passwords) stays 0600 and is never mounted.
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
dir=${1:-$here/secrets}
if [[ -e $dir/ca.pem ]]; then
  echo "$dir already holds secrets (ca.pem); remove it first to make new ones" >&2
  exit 1
fi
mkdir -p "$dir"
chmod 0700 "$dir"
bash "$here/../secure/make-certs.sh" "$dir" router > /dev/null
cd "$dir"
umask 077

# The router's own server certificate, signed by the same CA.
openssl req -newkey ec -pkeyopt ec_paramgen_curve:P-256 -nodes \
  -keyout router.key -out router.csr -subj "/CN=router" 2>/dev/null
printf 'subjectAltName=DNS:router,DNS:localhost,IP:127.0.0.1\nbasicConstraints=CA:FALSE\n' > router.ext
openssl x509 -req -in router.csr -CA ca.pem -CAkey ca.key -CAcreateserial \
  -days 365 -out router.pem -extfile router.ext 2>/dev/null
rm -f router.csr router.ext ca.srl

accounts=(daemon-a daemon-b view foxglove operator observer)
: > users.txt
for a in "${accounts[@]}"; do
  pw=$(openssl rand -hex 16)
  printf '%s\n' "$pw" > "$a.password"
  printf '%s:%s\n' "$a" "$pw" >> users.txt
done
for d in daemon-a daemon-b; do
  cat > "$d.json5" <<EOF
// zenoh credentials of $d, read as its [zenoh] config_file (made by
// deploy/compose/make-secrets.sh; the password is also in $d.password).
{ transport: { auth: { usrpwd: { user: "$d", password: "$(cat "$d.password")" } } } }
EOF
done

# What the containers mount; the rest (ca.key, operator.key and the
# operator's and observer's passwords, for the CLI on the host) stays 0600.
chmod 0644 ./*.pem router.key daemon.key viewer.key users.txt ./*.json5 \
  daemon-a.password daemon-b.password view.password foxglove.password
chmod 0600 ca.key operator.key operator.password observer.password
echo "wrote the secrets of compose.secure.yaml to $(pwd) (keep ca.key offline: it signs new certificates)"
