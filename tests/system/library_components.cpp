// A shared library of components, loaded by a hosting program because a
// system file lists it (libraries:), not linked into the program.
#include "pipeline.hpp"

namespace {

prime::system::Component echo() {
  return prime::system::Component{"test.library_echo"}
      .subscribes<pipeline::Count>("counts", {.capacity = 256})
      .publishes<pipeline::Count>("echoed", {.capacity = 256, .overflow = prime::Overflow::block})
      .build([](prime::system::Context& ctx) {
        prime::forward(ctx.input<pipeline::Count>("counts"),
                       [out = ctx.output<pipeline::Count>("echoed")](const pipeline::Count& c, prime::Clock::time_point stamp) {
                         (void)out.publish(pipeline::Count{c.n + 1000}, stamp);
                       });
      });
}

}  // namespace

PRIME_COMPONENT(echo());
