# prime_header_layer(<name> [EXPORT <export-set>] [LINKS <targets>...])
# A header-only Prime target `prime::<name>`: headers under ./include,
# exported for find_package(prime) in <export-set> (default primeTargets, the
# core that needs only Threads). A layer with third-party dependencies has an
# export set of its own, which primeConfig.cmake loads only once it has found
# them.
function(prime_header_layer name)
  cmake_parse_arguments(PARSE_ARGV 1 arg "" "EXPORT" "LINKS")
  if(NOT arg_EXPORT)
    set(arg_EXPORT primeTargets)
  endif()
  add_library(prime_${name} INTERFACE)
  add_library(prime::${name} ALIAS prime_${name})
  set_target_properties(prime_${name} PROPERTIES EXPORT_NAME ${name})
  target_include_directories(prime_${name} INTERFACE
    $<BUILD_INTERFACE:${CMAKE_CURRENT_SOURCE_DIR}/include>
    $<INSTALL_INTERFACE:${CMAKE_INSTALL_INCLUDEDIR}>)
  target_compile_features(prime_${name} INTERFACE cxx_std_23)
  target_link_libraries(prime_${name} INTERFACE ${arg_LINKS})
  install(TARGETS prime_${name} EXPORT ${arg_EXPORT})
  install(DIRECTORY include/ DESTINATION ${CMAKE_INSTALL_INCLUDEDIR})
endfunction()
