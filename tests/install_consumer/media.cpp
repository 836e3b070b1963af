// Links the media from an installed Prime: Shm (a compiled library) and
// Optimus (hiredis, msgpack-cxx). Needs no server and maps no shared memory.
#include <prime/optimus.hpp>
#include <prime/shm.hpp>
#include <prime/shm/inspect.hpp>

#include <string>
#include <vector>

int main() {
  const std::vector<std::string> words{"find_package", "prime", "shm", "optimus"};
  auto back = prime::optimus::decode_message<std::vector<std::string>>(prime::optimus::encode_message(words), "consumer");
  const prime::bounded_string<16> name{"robot"};
  // Looks for a domain that is not there, through libprime_shm.
  const bool no_domain = !prime::shm::inspect("prime-install-consumer-no-such-domain");
  return back && *back == words && name.size() == 5 && no_domain ? 0 : 1;
}
