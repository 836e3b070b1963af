#pragma once

#include <type_traits>

namespace prime::shm {

// The message type of a raw byte topic (images, point clouds): each message
// is 0 to max_message_size bytes, sized when it is loaned.
struct Bytes {};

// A message a shared-memory topic can carry: it is its bytes.
template <class T>
concept Message = std::is_same_v<T, Bytes> ||
                  (std::is_trivially_copyable_v<T> && std::is_trivially_destructible_v<T> && alignof(T) <= 64);

}  // namespace prime::shm
