#!/bin/sh
# A test certificate authority and certificates for mutual TLS between haptic-master,
# haptic-slave and the Zenoh router (openssl; EC P-256 keys, PKCS#8 PEM).
#
#   deploy/make_certs.sh DIR [--name NAME]... [--san SAN]... [--days N]
#
# DIR/ca.pem, DIR/ca.key: the CA (made if DIR has none, reused otherwise, so a second run
# adds certificates signed by the same CA). For every NAME (default: router master slave):
# DIR/NAME.pem and DIR/NAME.key, common name haptic-NAME (the CN the access control matches),
# extended key usage server and client auth, subject alternative names DNS:NAME,
# DNS:localhost, IP:127.0.0.1 and every --san (e.g. --san IP:192.168.1.10 --san DNS:rig-pc).
# A different DIR gives a different, unrelated CA. For a lab, not a production PKI.
set -eu

usage() { echo "usage: $0 DIR [--name NAME]... [--san SAN]... [--days N]" >&2; exit 2; }
[ $# -ge 1 ] || usage
dir=$1; shift
names=""; sans=""; days=365
while [ $# -gt 0 ]; do
    case $1 in
        --name) [ $# -ge 2 ] || usage; names="$names $2"; shift 2 ;;
        --san)  [ $# -ge 2 ] || usage; sans="$sans,$2"; shift 2 ;;
        --days) [ $# -ge 2 ] || usage; days=$2; shift 2 ;;
        *) usage ;;
    esac
done
[ -n "$names" ] || names="router master slave"
mkdir -p "$dir"
umask 077

if [ ! -f "$dir/ca.pem" ] || [ ! -f "$dir/ca.key" ]; then
    openssl genpkey -algorithm EC -pkeyopt ec_paramgen_curve:P-256 -out "$dir/ca.key"
    openssl req -x509 -new -key "$dir/ca.key" -sha256 -days "$days" \
        -subj "/O=haptic-teleop/CN=haptic-test-ca-$(date +%s)-$$" \
        -addext "basicConstraints=critical,CA:TRUE" \
        -addext "keyUsage=critical,keyCertSign,cRLSign" \
        -addext "subjectKeyIdentifier=hash" \
        -out "$dir/ca.pem"
fi

for name in $names; do
    ext="$dir/$name.ext"
    cat > "$ext" <<EXT
basicConstraints=critical,CA:FALSE
keyUsage=critical,digitalSignature,keyEncipherment
extendedKeyUsage=serverAuth,clientAuth
subjectKeyIdentifier=hash
authorityKeyIdentifier=keyid
subjectAltName=DNS:$name,DNS:localhost,IP:127.0.0.1$sans
EXT
    openssl genpkey -algorithm EC -pkeyopt ec_paramgen_curve:P-256 -out "$dir/$name.key"
    openssl req -new -key "$dir/$name.key" -subj "/O=haptic-teleop/CN=haptic-$name" \
        -out "$dir/$name.csr"
    openssl x509 -req -in "$dir/$name.csr" -CA "$dir/ca.pem" -CAkey "$dir/ca.key" \
        -CAcreateserial -sha256 -days "$days" -extfile "$ext" -out "$dir/$name.pem" 2>/dev/null
    rm -f "$dir/$name.csr" "$ext"
done
chmod 644 "$dir"/*.pem
echo "certificates in $dir: ca.pem$(for n in $names; do printf ' %s.pem' "$n"; done)" >&2
