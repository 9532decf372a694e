/* kpcn-dataset: scenes -> perturbed variants -> renders -> patch store (docs/dataset.md).
 *   kpcn-dataset plan    --scenes DIR -o DATASET [...]   pre-render augmentation + manifest
 *   kpcn-dataset run     DATASET [--jobs N] [--shard i/n] resumable, shardable rendering
 *   kpcn-dataset patches DATASET -o train.kps [...]      patch store with culling stats
 * Exit codes: 0 ok, 1 failure, 2 usage error, 130 interrupted. */
#include "ds.h"
#include "kpcn/common.h"

#include <string.h>

static void usage(FILE *f) {
  fprintf(f, "usage: kpcn-dataset plan|run|patches ... (kpcn-dataset CMD --help; --version)\n");
}

int main(int argc, char **argv) {
  if (argc < 2) {
    usage(stderr);
    return 2;
  }
  const char *cmd = argv[1];
  if (!strcmp(cmd, "plan")) return ds_cmd_plan(argc - 1, argv + 1);
  if (!strcmp(cmd, "run")) return ds_cmd_run(argc - 1, argv + 1);
  if (!strcmp(cmd, "patches")) return ds_cmd_patches(argc - 1, argv + 1);
  if (!strcmp(cmd, "-h") || !strcmp(cmd, "--help")) {
    usage(stdout);
    return 0;
  }
  if (!strcmp(cmd, "--version")) {
    printf("kpcn-dataset %s\n%s\n", KPCN_VERSION_STRING, kpcn_build_info());
    return 0;
  }
  ds_err("unknown command '%s'", cmd);
  usage(stderr);
  return 2;
}
