#include "services.hpp"

namespace prime::bench {

Message add(Message m) {
  ++m.counter;
  return m;
}

}  // namespace prime::bench
