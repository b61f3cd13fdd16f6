# The house's one rule, checked when the build is configured: the ground and
# the remote share only common/ (and common/protocol). No target defined
# under ground_station/ links a library defined under remote_site/, directly
# or through another library, and no remote_site/ target links a ground one.
# (The include side: the test `ground_and_remote_include_only_common`.)

# The targets `target` links, transitively (only targets of this project).
function(foresight_link_closure target out_var)
  set(seen "")
  set(todo ${target})
  while(todo)
    list(POP_FRONT todo t)
    if(NOT TARGET ${t} OR t IN_LIST seen)
      continue()
    endif()
    list(APPEND seen ${t})
    get_target_property(type ${t} TYPE)
    set(deps "")
    if(NOT type STREQUAL "INTERFACE_LIBRARY")
      get_target_property(d ${t} LINK_LIBRARIES)
      if(d)
        list(APPEND deps ${d})
      endif()
    endif()
    get_target_property(i ${t} INTERFACE_LINK_LIBRARIES)
    if(i)
      list(APPEND deps ${i})
    endif()
    foreach(dep IN LISTS deps)
      string(REGEX REPLACE "^\\$<LINK_ONLY:(.*)>$" "\\1" dep "${dep}")
      if(TARGET ${dep})
        list(APPEND todo ${dep})
      endif()
    endforeach()
  endwhile()
  list(REMOVE_ITEM seen ${target})
  set(${out_var} ${seen} PARENT_SCOPE)
endfunction()

# Every buildsystem target under `dir`, recursively.
function(foresight_targets_under dir out_var)
  get_property(targets DIRECTORY ${dir} PROPERTY BUILDSYSTEM_TARGETS)
  get_property(subdirs DIRECTORY ${dir} PROPERTY SUBDIRECTORIES)
  foreach(sub IN LISTS subdirs)
    foresight_targets_under(${sub} more)
    list(APPEND targets ${more})
  endforeach()
  set(${out_var} ${targets} PARENT_SCOPE)
endfunction()

# FATAL_ERROR naming the target and what it links when a target under
# `from_dir` reaches one defined under `to_dir`.
function(foresight_check_no_links from_dir to_dir)
  foresight_targets_under(${from_dir} targets)
  foreach(t IN LISTS targets)
    foresight_link_closure(${t} closure)
    foreach(dep IN LISTS closure)
      get_target_property(dep_dir ${dep} SOURCE_DIR)
      cmake_path(IS_PREFIX to_dir "${dep_dir}" NORMALIZE inside)
      if(inside)
        file(RELATIVE_PATH rel_from ${CMAKE_SOURCE_DIR} ${from_dir})
        file(RELATIVE_PATH rel_to ${CMAKE_SOURCE_DIR} ${to_dir})
        message(FATAL_ERROR "${t} (${rel_from}/) links ${dep}, a library of ${rel_to}/: the two sides share only common/")
      endif()
    endforeach()
  endforeach()
endfunction()

foresight_check_no_links(${CMAKE_SOURCE_DIR}/ground_station ${CMAKE_SOURCE_DIR}/remote_site)
foresight_check_no_links(${CMAKE_SOURCE_DIR}/remote_site ${CMAKE_SOURCE_DIR}/ground_station)

# The include side, as a test: no file under ground_station/ (tests
# included) includes a header of a remote_site/ library, and the reverse. The
# include folders are each side's own (foresight/<library>/), found here.
function(foresight_include_names side out_var)
  file(GLOB dirs LIST_DIRECTORIES true ${CMAKE_SOURCE_DIR}/${side}/*/include/foresight/*)
  set(names "")
  foreach(d IN LISTS dirs)
    if(IS_DIRECTORY ${d})
      get_filename_component(n ${d} NAME)
      list(APPEND names ${n})
    endif()
  endforeach()
  list(REMOVE_DUPLICATES names)
  list(JOIN names "|" joined)
  set(${out_var} ${joined} PARENT_SCOPE)
endfunction()
foresight_include_names(remote_site remote_includes)
foresight_include_names(ground_station ground_includes)
add_test(NAME ground_and_remote_include_only_common
  COMMAND sh -c "cd ${CMAKE_SOURCE_DIR} && \
bad=$(grep -rnE '#include \"foresight/(${remote_includes})/' ground_station; \
grep -rnE '#include \"foresight/(${ground_includes}|cli)/' remote_site); \
if [ -n \"$bad\" ]; then printf '%s\\n' \"$bad\"; echo 'ground and remote meet only in common/'; exit 1; fi")
