// A program that hosts the pipeline's components, as `prime launch` and the
// placement tests start it (prime::system::run).
#include "pipeline.hpp"

int main(int argc, char** argv) {
  pipeline::register_all();
  return prime::system::run(argc, argv);
}
