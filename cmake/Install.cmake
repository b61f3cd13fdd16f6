# Installation and Debian packages (issue 14; docs/deploy.md).
#
#   cd build && cpack -G DEB
#     foresight-remote_<version>_<arch>.deb   the cabinet: daemon, systemd units,
#                                              /etc/foresight config, CAN bring-up
#     foresight-ground_<version>_<arch>.deb   the operator's machine: the CLI + config
#   DESTDIR=/tmp/stage cmake --install build --component remote   (a staging tree;
#     /etc, /lib/systemd are absolute destinations, everything else under the prefix)
#
# The packages' Debian dependencies come from dpkg-shlibdeps on the binaries
# (our own libraries are static) plus the few loaded at run time, named below.
# The remote package carries no ground library (no OpenCV, no GL): its binary
# links none (remote_site/deploy/test_packages.sh checks, test_check runs it).

include(GNUInstallDirs)
# `ninja install` / cpack do not rebuild every target of the tree first.
set(CMAKE_SKIP_INSTALL_ALL_DEPENDENCY ON)

set(_deploy ${CMAKE_SOURCE_DIR}/remote_site/deploy)
set(_stage ${CMAKE_BINARY_DIR}/deploy)

# ---- the cabinet's remote.yaml: the repository's with the real CAN buses --------------
# config/remote.yaml names the cabinet interface beside each mock bus
# ("interface: mock, ...}   # real robot: can0"); the installed file uses it.
set_property(DIRECTORY APPEND PROPERTY CMAKE_CONFIGURE_DEPENDS ${CMAKE_SOURCE_DIR}/config/remote.yaml)
file(READ ${CMAKE_SOURCE_DIR}/config/remote.yaml _remote_yaml)
string(REGEX REPLACE "interface: mock, bitrate: ([0-9]+)}([ ]*)# real robot: (can[0-9]+)"
       "interface: \\3, bitrate: \\1}\\2# the cabinet's SocketCAN interface (--sim: a mock bus)"
       _remote_yaml "${_remote_yaml}")
string(REPLACE "path: foresight-journal.db    # relative to the working directory"
       "path: foresight-journal.db    # relative to the working directory (the unit: /var/lib/foresight)"
       _remote_yaml "${_remote_yaml}")
# The cabinet runs DDS Security (docs/deploy.md, section 3): the daemon refuses to
# start until the identities exist in /etc/foresight/dds-security.
string(REPLACE "security: \"\"                  # installed: dds-security (/etc/foresight/dds-security)"
       "security: dds-security        # /etc/foresight/dds-security: make_dds_security.sh (docs/deploy.md, 3)"
       _remote_yaml "${_remote_yaml}")
if(NOT _remote_yaml MATCHES "security: dds-security")
  message(FATAL_ERROR "cmake/Install.cmake: config/remote.yaml's controller.link.security line changed: update the "
                      "installed file's replacement")
endif()
file(WRITE ${_stage}/remote.yaml
     "# Installed by the foresight-remote package (a conffile: your edits are kept).\n"
     "# Check it before the first motion: foresight-remote check --config /etc/foresight/remote.yaml\n"
     "${_remote_yaml}")

# ---- package maintainer scripts (remote) ------------------------------------------------
# The drives' SDO lists (remote.yaml's sdo_file: paths, relative to it).
file(GLOB _drive_files RELATIVE ${CMAKE_SOURCE_DIR}/config/drives CONFIGURE_DEPENDS ${CMAKE_SOURCE_DIR}/config/drives/*)
list(TRANSFORM _drive_files PREPEND /etc/foresight/drives/ OUTPUT_VARIABLE _drive_conffiles)
set(_remote_conffiles
    /etc/foresight/remote.yaml /etc/foresight/robot.urdf /etc/foresight/oru.yaml /etc/foresight/scene.yaml
    ${_drive_conffiles}
    /etc/default/foresight-remote /etc/systemd/system/foresight-remote.service.d/cpu.conf)
list(JOIN _remote_conffiles "\n" _conf)
file(WRITE ${_stage}/remote/conffiles "${_conf}\n")
# Reload the units; never enable or start the daemon on install: the first
# start is the operator's decision after `foresight-remote check` (docs/deploy.md).
file(WRITE ${_stage}/remote/postinst
     "#!/bin/sh\nset -e\nif [ -d /run/systemd/system ]; then systemctl daemon-reload >/dev/null || true; fi\n"
     "if [ \"$1\" = configure ]; then\n"
     "  echo 'foresight-remote: installed (not started). Next: foresight-remote check --config "
     "/etc/foresight/remote.yaml; then systemctl enable --now foresight-remote'\n"
     "fi\nexit 0\n")
file(WRITE ${_stage}/remote/postrm
     "#!/bin/sh\nset -e\nif [ -d /run/systemd/system ]; then systemctl daemon-reload >/dev/null || true; fi\nexit 0\n")
file(WRITE ${_stage}/remote/prerm
     "#!/bin/sh\nset -e\n"
     "if [ -d /run/systemd/system ] && [ \"$1\" = remove ]; then systemctl stop foresight-remote.service || true; fi\n"
     "exit 0\n")
file(CHMOD ${_stage}/remote/postinst ${_stage}/remote/postrm ${_stage}/remote/prerm
     PERMISSIONS OWNER_READ OWNER_WRITE OWNER_EXECUTE GROUP_READ GROUP_EXECUTE WORLD_READ WORLD_EXECUTE)
file(WRITE ${_stage}/ground/foresight-ground.sh
     "# The foresight CLI reads its configuration from /etc/foresight-ground unless told otherwise.\n"
     ": \"\${FORESIGHT_CONFIG_DIR:=/etc/foresight-ground}\"\nexport FORESIGHT_CONFIG_DIR\n")
# The station's ground.yaml: DDS Security on (docs/deploy.md, section 3).
set_property(DIRECTORY APPEND PROPERTY CMAKE_CONFIGURE_DEPENDS ${CMAKE_SOURCE_DIR}/config/ground.yaml)
file(READ ${CMAKE_SOURCE_DIR}/config/ground.yaml _ground_yaml)
string(REPLACE "security: \"\"                  # installed: dds-security (/etc/foresight-ground/dds-security)"
       "security: dds-security        # /etc/foresight-ground/dds-security: this station's identity (docs/deploy.md, 3)"
       _ground_yaml "${_ground_yaml}")
if(NOT _ground_yaml MATCHES "security: dds-security")
  message(FATAL_ERROR "cmake/Install.cmake: config/ground.yaml's link.security line changed: update the "
                      "installed file's replacement")
endif()
file(WRITE ${_stage}/ground.yaml "# Installed by the foresight-ground package (a conffile: your edits are kept).\n${_ground_yaml}")
file(WRITE ${_stage}/ground/conffiles
     "/etc/foresight-ground/ground.yaml\n/etc/foresight-ground/robot.urdf\n/etc/foresight-ground/oru.yaml\n/etc/foresight-ground/scene.yaml\n"
     "/etc/foresight-ground/remote.yaml\n/etc/foresight-ground/scripts/oru_changeout.task\n"
     "/etc/profile.d/foresight-ground.sh\n")

# ---- component `remote`: the foresight-remote package -----------------------------------
install(TARGETS foresight-remote RUNTIME DESTINATION ${CMAKE_INSTALL_BINDIR} COMPONENT remote)
install(FILES ${_deploy}/systemd/foresight-remote.service ${_deploy}/can/foresight-can.service
        DESTINATION /lib/systemd/system COMPONENT remote)
install(FILES ${_deploy}/systemd/foresight-remote.service.d/cpu.conf
        DESTINATION /etc/systemd/system/foresight-remote.service.d COMPONENT remote)
install(FILES ${_deploy}/systemd/foresight-remote.default RENAME foresight-remote
        DESTINATION /etc/default COMPONENT remote)
# Config templates; scene.yaml and oru.yaml serve --sim (the simulated work site).
install(FILES ${_stage}/remote.yaml ${CMAKE_SOURCE_DIR}/config/robot.urdf ${CMAKE_SOURCE_DIR}/config/oru.yaml
              ${CMAKE_SOURCE_DIR}/config/scene.yaml
        DESTINATION /etc/foresight COMPONENT remote)
install(DIRECTORY ${CMAKE_SOURCE_DIR}/config/drives/ DESTINATION /etc/foresight/drives COMPONENT remote)
install(PROGRAMS ${_deploy}/can/can-setup.sh DESTINATION lib/foresight COMPONENT remote)
install(FILES ${_deploy}/can/80-foresight-can.network ${_deploy}/can/80-foresight-can.link
        DESTINATION ${CMAKE_INSTALL_DATADIR}/foresight-remote/can COMPONENT remote)
install(PROGRAMS ${CMAKE_SOURCE_DIR}/scripts/make_dds_security.sh
        DESTINATION ${CMAKE_INSTALL_DATADIR}/foresight-remote/scripts COMPONENT remote)
install(FILES ${CMAKE_SOURCE_DIR}/docs/deploy.md ${CMAKE_SOURCE_DIR}/docs/journal.md
        DESTINATION ${CMAKE_INSTALL_DATADIR}/doc/foresight-remote COMPONENT remote)

# ---- component `ground`: the foresight-ground package -----------------------------------
install(TARGETS foresight RUNTIME DESTINATION ${CMAKE_INSTALL_BINDIR} COMPONENT ground)
install(FILES ${CMAKE_SOURCE_DIR}/config/robot.urdf ${CMAKE_SOURCE_DIR}/config/oru.yaml
              ${CMAKE_SOURCE_DIR}/config/scene.yaml ${CMAKE_SOURCE_DIR}/config/remote.yaml
        DESTINATION /etc/foresight-ground COMPONENT ground)
install(FILES ${_stage}/ground.yaml DESTINATION /etc/foresight-ground COMPONENT ground)
install(DIRECTORY ${CMAKE_SOURCE_DIR}/config/scripts/ DESTINATION /etc/foresight-ground/scripts COMPONENT ground)
install(DIRECTORY ${CMAKE_SOURCE_DIR}/config/drives/ DESTINATION /etc/foresight-ground/drives COMPONENT ground)
install(FILES ${_stage}/ground/foresight-ground.sh DESTINATION /etc/profile.d COMPONENT ground)
install(PROGRAMS ${CMAKE_SOURCE_DIR}/scripts/make_dds_security.sh
        DESTINATION ${CMAKE_INSTALL_DATADIR}/foresight-ground/scripts COMPONENT ground)
install(FILES ${CMAKE_SOURCE_DIR}/docs/operator.md DESTINATION ${CMAKE_INSTALL_DATADIR}/doc/foresight-ground
        COMPONENT ground)

# ---- CPack: two .deb packages -------------------------------------------------------------
set(CPACK_GENERATOR DEB)
set(CPACK_PACKAGE_NAME foresight)
set(CPACK_PACKAGE_VENDOR "Foresight")
set(CPACK_PACKAGE_CONTACT "Foresight maintainers <foresight@localhost>")
set(CPACK_PACKAGE_VERSION ${PROJECT_VERSION})
set(CPACK_PACKAGING_INSTALL_PREFIX /usr)
set(CPACK_COMPONENTS_ALL remote ground)
set(CPACK_DEB_COMPONENT_INSTALL ON)
set(CPACK_DEBIAN_FILE_NAME DEB-DEFAULT)
set(CPACK_DEBIAN_PACKAGE_SHLIBDEPS ON)
set(CPACK_DEBIAN_PACKAGE_SECTION misc)
set(CPACK_DEBIAN_PACKAGE_PRIORITY optional)
set(CPACK_DEBIAN_COMPRESSION_TYPE gzip)  # faster than xz: the package test builds both

set(CPACK_DEBIAN_REMOTE_PACKAGE_NAME foresight-remote)
string(CONCAT CPACK_COMPONENT_REMOTE_DESCRIPTION
    "Foresight remote controller for the robot cabinet\n"
    "The foresight-remote daemon: real-time control of the CiA 402 drives over SocketCAN, wrist F/T compliance, "
    "the LST tool over Modbus, the DDS link to the ground and the journal; its systemd unit, CAN bring-up and "
    "configuration templates in /etc/foresight.")
# Beside the shared libraries (libddsc0debian, which also holds Cyclone's DDS Security
# plugins, comes from shlibdeps): `check` reads the CAN state with ip, the unit needs systemd.
set(CPACK_DEBIAN_REMOTE_PACKAGE_DEPENDS "iproute2, systemd")
set(CPACK_DEBIAN_REMOTE_PACKAGE_RECOMMENDS "systemd-timesyncd | chrony, openssl")
set(CPACK_DEBIAN_REMOTE_PACKAGE_CONTROL_EXTRA
    "${_stage}/remote/conffiles;${_stage}/remote/postinst;${_stage}/remote/prerm;${_stage}/remote/postrm")

set(CPACK_DEBIAN_GROUND_PACKAGE_NAME foresight-ground)
string(CONCAT CPACK_COMPONENT_GROUND_DESCRIPTION
    "Foresight ground station (operator CLI)\n"
    "The foresight command: camera calibration with the arm as fixture, multi-view ORU localization, "
    "calibrated overlays and motion preview (OSMesa/EGL), planning, and the DDS link to the robot cabinet.")
# Mesa's drivers are loaded at run time by OSMesa/EGL.
set(CPACK_DEBIAN_GROUND_PACKAGE_DEPENDS "libgl1-mesa-dri, libegl-mesa0")
set(CPACK_DEBIAN_GROUND_PACKAGE_CONTROL_EXTRA "${_stage}/ground/conffiles")

include(CPack)
