#pragma once

namespace prime::system {

// The main of a program that hosts components (registered with
// PRIME_COMPONENT), as `prime launch` starts it:
//
//   program --prime-system FILE --placement NAME --process NAME [--param component.name=value]... [--domain D]
//       hosts that process of the placement (in domain D instead of the
//       file's `system`) until SIGINT or SIGTERM; when
//       the environment names PRIME_READY_FD, writes "ready" to it once
//       every component is built (its services served, its topics open);
//   program --prime-check FILE --placement NAME [--param ...]
//       prints what is wrong with the placement for the components this
//       program has (exit 1), or the order to start its processes (exit 0);
//   program --prime-describe
//       prints the components it has: ports, parameters, triggers.
//
// Returns the process's exit code: 0 once stopped, 1 when it could not
// start (with the reason on stderr), 2 for wrong arguments.
int run(int argc, char** argv);

}  // namespace prime::system
