#pragma once

namespace prime::optimus::detail {

// libprime_optimus's ABI version (its SOVERSION, read from here by
// media/optimus/CMakeLists.txt): raise it whenever a compiled function's
// signature or a type its callers lay out changes.
inline constexpr int kAbi = 2;

}  // namespace prime::optimus::detail
