// Links the media with third-party dependencies (Boost, hiredis, msgpack-cxx)
// from an installed Prime. Needs no server and maps no shared memory.
#include <prime/optimus.hpp>
#include <prime/shm.hpp>

#include <string>
#include <vector>

int main() {
  const std::vector<std::string> words{"find_package", "prime", "shm", "optimus"};
  auto back = prime::optimus::decode_message<std::vector<std::string>>(prime::optimus::encode_message(words), "consumer");
  const prime::bounded_string<16> name{"robot"};
  return back && *back == words && name.size() == 5 ? 0 : 1;
}
