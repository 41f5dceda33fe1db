"""`farm model [--out DIR] [--library DIR] [--port P] [--host H] [--token T] [--tls-cert C --tls-key K |
--tls-self-signed]`: serve the modelling page, where a tree is shaped by hand (strokes and lobes, main branches,
brush) in a desktop browser or a WebXR headset and grown live; see docs/modelling.md.

--out DIR keeps saved sessions (and a self-signed certificate); --library DIR is the asset library that "send to
library" builds into. A headset on the network needs HTTPS: --host 0.0.0.0 with --tls-self-signed (check the
printed fingerprint on the headset) or a certificate of your own.
"""
from __future__ import annotations

import argparse
import sys

from farm.commands import CommandLineError, check_flag_int

# What a command runs is imported inside its functions: `farm --help` loads every command module (start-up time).


def register(subparsers) -> None:
    parser = subparsers.add_parser("model", help="model a tree by hand in a browser or VR headset, grown live",
                                   description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", metavar="DIR", help="folder for saved sessions (default: saving to the server is off)")
    parser.add_argument("--library", metavar="DIR", help="asset library folder that `send to library` builds into")
    parser.add_argument("--port", type=int, default=8766, help="port to listen on (default 8766; 0 picks a free one)")
    parser.add_argument("--host", default="127.0.0.1", help="address to bind (default 127.0.0.1: this machine only)")
    parser.add_argument("--token", help="access token (default: a new random one)")
    parser.add_argument("--tls-cert", metavar="C", help="HTTPS certificate (PEM), with --tls-key")
    parser.add_argument("--tls-key", metavar="K", help="HTTPS private key (PEM), with --tls-cert")
    parser.add_argument("--tls-self-signed", action="store_true",
                        help="serve HTTPS with a new self-signed certificate (its SHA-256 fingerprint is printed)")
    parser.set_defaults(run=run)


def _tls(args: argparse.Namespace) -> tuple[tuple[str, str] | None, str | None]:
    """(certificate, key) files and the fingerprint to print, from the flags (checked before anything starts)."""
    import tempfile

    from farm.modelling.certificate import self_signed_certificate

    if args.tls_self_signed and (args.tls_cert or args.tls_key):
        raise CommandLineError("--tls-self-signed makes its own certificate: pass it or --tls-cert/--tls-key, "
                               "not both")
    if bool(args.tls_cert) != bool(args.tls_key):
        raise CommandLineError("--tls-cert and --tls-key go together: pass both or neither")
    if args.tls_cert:
        return (args.tls_cert, args.tls_key), None
    if not args.tls_self_signed:
        return None, None
    folder = f"{args.out}/tls" if args.out else tempfile.mkdtemp(prefix="farm-model-tls-")
    cert, key, fingerprint = self_signed_certificate(folder, [args.host, *_network_names(args.host)])
    return (str(cert), str(key)), fingerprint


def _network_names(host: str) -> list[str]:
    """This machine's name and addresses, when the server listens on every address (0.0.0.0 or ::): the names a
    headset on the network reaches it by."""
    import socket

    if host not in ("0.0.0.0", "::"):
        return []
    name = socket.gethostname()
    try:
        addresses = socket.gethostbyname_ex(name)[2]
    except OSError:
        addresses = []
    return [name, *[a for a in addresses if not a.startswith("127.")]]


def run(args: argparse.Namespace) -> int:
    from farm.modelling.server import create_model_app
    from farm.modelling.service import ModelService
    from farm.token_server import TokenServer, check_token, listen_socket, new_token

    check_flag_int("--port", args.port, 0, 65535)
    token = check_token(args.token) if args.token else new_token()
    tls, fingerprint = _tls(args)
    sock = listen_socket(args.host, args.port)  # a taken port is refused before anything is made
    server = TokenServer(create_model_app(ModelService(args.out, args.library), token), args.host, sock=sock,
                         tls=tls)
    if args.host not in ("127.0.0.1", "localhost", "::1"):
        print(f"warning: listening on {args.host}: anyone who can reach it and has the token can edit the session",
              file=sys.stderr)
        if tls is None:
            print("warning: plain HTTP: a headset's browser offers VR only over HTTPS (--tls-self-signed)",
                  file=sys.stderr)
    if fingerprint:
        print(f"self-signed certificate SHA-256 {fingerprint}")
    print(f"open {server.url(token)}")
    for name in _network_names(args.host):
        print(f"  from the network: {server.url(token).replace(f'//{args.host}:', f'//{name}:', 1)}")
    sys.stdout.flush()
    server.run()
    return 0
