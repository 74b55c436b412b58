#!/usr/bin/env bash
# A throw-away PKI for trying the secure deployment (config/docker-secure.toml):
# a CA, the daemon's certificate (names: localhost, 127.0.0.1 and $DAEMON_NAME)
# and an operator's client certificate (CN "operator", the name the config's
# [zenoh.access] operator_certificates admits). For production use your own CA.
#
#   deploy/secure/make-certs.sh DIR [DAEMON_NAME]
#
# Writes DIR/ca.pem, DIR/daemon.{pem,key}, DIR/operator.{pem,key}, and a
# DIR/viewer.{pem,key} that the CA signs but the policy does not let switch.
set -euo pipefail
dir=${1:?usage: make-certs.sh DIR [DAEMON_NAME]}
name=${2:-lodcloth}
mkdir -p "$dir"
cd "$dir"
umask 077

openssl req -x509 -newkey ec -pkeyopt ec_paramgen_curve:P-256 -nodes -days 365 \
  -keyout ca.key -out ca.pem -subj "/CN=lodcloth deployment CA" 2>/dev/null

issue() { # CN SAN-line
  local cn=$1 san=$2
  openssl req -newkey ec -pkeyopt ec_paramgen_curve:P-256 -nodes \
    -keyout "$cn.key" -out "$cn.csr" -subj "/CN=$cn" 2>/dev/null
  printf 'subjectAltName=%s\nbasicConstraints=CA:FALSE\n' "$san" > "$cn.ext"
  openssl x509 -req -in "$cn.csr" -CA ca.pem -CAkey ca.key -CAcreateserial \
    -days 365 -out "$cn.pem" -extfile "$cn.ext" 2>/dev/null
  rm -f "$cn.csr" "$cn.ext"
}
issue daemon "DNS:localhost,IP:127.0.0.1,DNS:$name"
issue operator "DNS:operator"
issue viewer "DNS:viewer"
rm -f ca.srl
# zenoh reads PKCS#8, SEC1 or RSA keys; the files stay readable by you only.
echo "wrote $(pwd)/{ca.pem,daemon.pem,daemon.key,operator.pem,operator.key,viewer.pem,viewer.key}"
echo "keep ca.key offline: it signs new operators"
