#pragma once

#include "prime/shm/detail/topic.hpp"

namespace prime::shm::detail {

// A publisher taking over a topic whose publisher died: the chunks the ring
// names become the new publisher's, the rest (the dead one's loans, spares
// and chunks leaving the ring) are freed, whatever step of a publish it
// died in; and the topic goes on after the last sequence that reached the
// ring. Reads only within the segment's own bounds (Places).
void recover_from_dead_publisher(Topic& topic);

}  // namespace prime::shm::detail
