"""`gmr show` (being written)."""


def register(sub):
    p = sub.add_parser("show", help="(being written)")
    p.set_defaults(fn=lambda args: 0)
    return p
