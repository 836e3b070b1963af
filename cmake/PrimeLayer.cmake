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

# prime_compiled_layer(<name> SOURCES <files>... ABI <n> [EXPORT <export-set>]
#                      [INSTALL_DETAIL] [LINKS <targets>...]
#                      [BUILD_LINKS <targets>...] [PRIVATE_LINKS <targets>...])
# A compiled Prime medium: `prime::<name>` (shared, libprime_<name>.so.<n>)
# and `prime::<name>_static` (static, libprime_<name>.a), from one set of
# objects, headers under ./include. LINKS reach the users. BUILD_LINKS
# (header-only libraries the sources use) stay inside the library: no user
# translation unit includes them and an installed Prime does not ask for
# them. PRIVATE_LINKS are linked into the library, not into its users'
# compilations (the static library's users link them too). <n> is the
# library's ABI version (SOVERSION). Headers under include/.../detail/ are
# the library's own and are not installed, unless INSTALL_DETAIL says the
# public headers still include some.
function(prime_compiled_layer name)
  cmake_parse_arguments(PARSE_ARGV 1 arg "INSTALL_DETAIL" "EXPORT;ABI" "SOURCES;LINKS;BUILD_LINKS;PRIVATE_LINKS")
  if(NOT arg_EXPORT)
    set(arg_EXPORT primeTargets)
  endif()
  add_library(prime_${name}_objects OBJECT ${arg_SOURCES})
  set_target_properties(prime_${name}_objects PROPERTIES POSITION_INDEPENDENT_CODE ON)
  target_include_directories(prime_${name}_objects PRIVATE ${CMAKE_CURRENT_SOURCE_DIR}/include)
  target_compile_features(prime_${name}_objects PRIVATE cxx_std_23)
  target_compile_options(prime_${name}_objects PRIVATE -Wall -Wextra)
  target_link_libraries(prime_${name}_objects PRIVATE ${arg_LINKS} ${arg_BUILD_LINKS} ${arg_PRIVATE_LINKS})
  foreach(kind IN ITEMS SHARED STATIC)
    if(kind STREQUAL "SHARED")
      set(target prime_${name})
      set(export_name ${name})
    else()
      set(target prime_${name}_static)
      set(export_name ${name}_static)
    endif()
    add_library(${target} ${kind} $<TARGET_OBJECTS:prime_${name}_objects>)
    add_library(prime::${export_name} ALIAS ${target})
    set_target_properties(${target} PROPERTIES EXPORT_NAME ${export_name} OUTPUT_NAME prime_${name}
                                               VERSION ${PROJECT_VERSION} SOVERSION ${arg_ABI})
    target_include_directories(${target} PUBLIC
      $<BUILD_INTERFACE:${CMAKE_CURRENT_SOURCE_DIR}/include>
      $<INSTALL_INTERFACE:${CMAKE_INSTALL_INCLUDEDIR}>)
    target_compile_features(${target} PUBLIC cxx_std_23)
    target_link_libraries(${target} PUBLIC ${arg_LINKS} PRIVATE ${arg_PRIVATE_LINKS})
    install(TARGETS ${target} EXPORT ${arg_EXPORT}
            LIBRARY DESTINATION ${CMAKE_INSTALL_LIBDIR} ARCHIVE DESTINATION ${CMAKE_INSTALL_LIBDIR})
  endforeach()
  if(arg_INSTALL_DETAIL)
    install(DIRECTORY include/ DESTINATION ${CMAKE_INSTALL_INCLUDEDIR})
  else()
    install(DIRECTORY include/ DESTINATION ${CMAKE_INSTALL_INCLUDEDIR} PATTERN detail EXCLUDE)
  endif()
endfunction()

# prime_abi(<var> <header> <constant>): the number `<constant> = <n>` sets
# in <header>, where the library's ABI version is kept beside its layout
# versions.
function(prime_abi var header constant)
  file(STRINGS ${header} line REGEX "${constant} = [0-9]+")
  string(REGEX MATCH "${constant} = ([0-9]+)" _ "${line}")
  if(NOT CMAKE_MATCH_1)
    message(FATAL_ERROR "prime: ${header} sets no ${constant}")
  endif()
  set(${var} ${CMAKE_MATCH_1} PARENT_SCOPE)
endfunction()
