#!/usr/bin/env bash
# Throwaway-or-real certificates for the secure recipe (deploy/secure/README.md), made with openssl.
#
#   make-certs.sh OUT_DIR [ROUTER_HOST] [NAME ...]
#
# OUT_DIR      gets ca.pem/ca-key.pem (the site CA; keep ca-key.pem offline in production)
#              and NAME.pem/NAME-key.pem per name, signed by that CA.
# ROUTER_HOST  the router's DNS name or IP address, put in its certificate's subjectAltName
#              (clients verify it); default 127.0.0.1.
# NAME ...     client identities, default: vpp-service viewer rig0 rig1. The certificate's
#              common name (CN) is NAME: the router's ACL (router.json5) matches it, so a rig's
#              certificate must be named exactly like the rig (`service.rig`).
# An existing CA in OUT_DIR is reused, so more clients can be added later.
set -euo pipefail
out=${1:?usage: make-certs.sh OUT_DIR [ROUTER_HOST] [NAME ...]}
host=${2:-127.0.0.1}
shift $(( $# >= 2 ? 2 : $# ))
names=("$@")
[ ${#names[@]} -gt 0 ] || names=(vpp-service viewer rig0 rig1)
days=${CERT_DAYS:-825}
mkdir -p "$out"
cd "$out"
umask 077
if [ ! -f ca.pem ]; then
  openssl req -x509 -newkey ec -pkeyopt ec_paramgen_curve:P-256 -nodes -days "$days" \
    -subj "/CN=vpp-site-ca" -keyout ca-key.pem -out ca.pem \
    -addext "basicConstraints=critical,CA:TRUE" -addext "keyUsage=critical,keyCertSign,cRLSign" 2>/dev/null
fi
if [[ $host =~ ^[0-9.]+$ || $host == *:* ]]; then san="IP:$host"; else san="DNS:$host"; fi
sign() {  # sign NAME SAN USAGE
  local name=$1 altname=$2 usage=$3
  openssl req -newkey ec -pkeyopt ec_paramgen_curve:P-256 -nodes -subj "/CN=$name" \
    -keyout "$name-key.pem" -out "$name.csr" 2>/dev/null
  printf 'basicConstraints=critical,CA:FALSE\nkeyUsage=critical,digitalSignature\nextendedKeyUsage=%s\nsubjectAltName=%s\n' \
    "$usage" "$altname" > "$name.ext"
  openssl x509 -req -in "$name.csr" -CA ca.pem -CAkey ca-key.pem -CAcreateserial -days "$days" \
    -extfile "$name.ext" -out "$name.pem" 2>/dev/null
  rm -f "$name.csr" "$name.ext"
}
sign router "$san" serverAuth,clientAuth
for n in "${names[@]}"; do
  sign "$n" "DNS:$n" clientAuth
done
chmod 644 ./*.pem
chmod 600 ./*-key.pem
echo "certificates in $out: ca.pem router.pem ${names[*]/%/.pem}"
