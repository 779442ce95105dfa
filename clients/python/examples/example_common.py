"""What the example scripts share: the flags that name a daemon, a sequence and a map, the
client they make, and the ATE line they end with. The scripts import it from their own folder
(Python puts a script's folder first on sys.path)."""

from plenoxd_client import Client
from plenoxd_client.trajectory import ate


def add_common_arguments(parser):
    """--server, --dataset, --map, --token-file, --root-cert, --max-frames, --voxel-size."""
    parser.add_argument("--server", required=True, help="HOST:PORT of plenoxd")
    parser.add_argument("--dataset", required=True, help="sequence folder in the TUM layout")
    parser.add_argument("--map", required=True,
                        help="map name ([A-Za-z0-9_.-], 1-64 characters)")
    parser.add_argument("--token-file", help="file with the daemon's bearer token")
    parser.add_argument("--root-cert",
                        help="PEM of the CA that signed the daemon's TLS certificate")
    parser.add_argument("--max-frames", type=int, default=0, help="use only the first N frames")
    parser.add_argument("--voxel-size", type=float, default=0.0,
                        help="voxel size in metres of a new map (0 = the server default)")


def make_client(args):
    """A Client for args.server with the token of args.token_file (ends trimmed) and TLS with
    args.root_cert when given."""
    token = None
    if args.token_file:
        with open(args.token_file, "r", encoding="utf-8") as f:
            token = f.read().strip()
    return Client(args.server, token=token, root_certificates=args.root_cert)


def print_ate(estimates, groundtruth):
    """"ATE (no alignment, N frames): rmse .. cm, mean .. cm, max .. cm" of {timestamp: (t, q)}
    against TumDataset.groundtruth()."""
    error = ate(estimates, groundtruth)
    if error is None:
        print("ATE: no ground truth to compare with")
    else:
        print(f"ATE (no alignment, {error['matched']} frames): rmse {100 * error['rmse']:.2f} cm, "
              f"mean {100 * error['mean']:.2f} cm, max {100 * error['max']:.2f} cm")
