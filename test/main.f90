!> Test driver: runs every suite, or one suite, or one test of a suite:
!>     fpm test -- [SUITE [TEST]]
!> Ends with the line "N passed, N failed, N skipped" and a non-zero exit code on any failure.
program tester
   use, intrinsic :: iso_fortran_env, only: output_unit, error_unit
   use anm_testing, only: testsuite_type, new_testsuite, run_testsuite
   use test_core, only: collect_core
   use test_sh, only: collect_sh
   use test_shapes, only: collect_shapes
   use test_geometry, only: collect_geometry
   use test_io, only: collect_io
   use test_config, only: collect_config
   use test_parking, only: collect_parking
   use test_packing, only: collect_packing
   use test_shells, only: collect_shells
   use test_contact, only: collect_contact
   use test_slicing, only: collect_slicing
   use test_audit, only: collect_audit
   use test_cli, only: collect_cli
   use test_api, only: collect_api
   use test_dense, only: collect_dense
   use test_kind_cache, only: collect_kind_cache
   implicit none
   type(testsuite_type), allocatable :: suites(:)
   character(len=256) :: suite_name, test_name
   integer :: i, npass, nfail, nskip
   logical :: found

   suites = [new_testsuite("core", collect_core), new_testsuite("sh", collect_sh), &
             new_testsuite("shapes", collect_shapes), new_testsuite("geometry", collect_geometry), &
             new_testsuite("io", collect_io), new_testsuite("config", collect_config), &
             new_testsuite("parking", collect_parking), new_testsuite("packing", collect_packing), &
             new_testsuite("shells", collect_shells), &
             new_testsuite("contact", collect_contact), new_testsuite("slicing", collect_slicing), &
             new_testsuite("audit", collect_audit), new_testsuite("cli", collect_cli), &
             new_testsuite("api", collect_api), new_testsuite("dense", collect_dense), &
             new_testsuite("kindcache", collect_kind_cache)]
   npass = 0
   nfail = 0
   nskip = 0
   suite_name = ""
   test_name = ""
   if (command_argument_count() >= 1) call get_command_argument(1, suite_name)
   if (command_argument_count() >= 2) call get_command_argument(2, test_name)
   found = .false.
   do i = 1, size(suites)
      if (len_trim(suite_name) > 0 .and. suites(i)%name /= trim(suite_name)) cycle
      found = .true.
      write (output_unit, '(a)') "suite "//suites(i)%name
      if (len_trim(test_name) > 0) then
         call run_testsuite(suites(i), npass, nfail, nskip, trim(test_name))
      else
         call run_testsuite(suites(i), npass, nfail, nskip)
      end if
   end do
   if (.not. found) then
      write (error_unit, '(a)') "no suite named '"//trim(suite_name)//"'"
      nfail = nfail + 1
   end if
   write (output_unit, '(i0,a,i0,a,i0,a)') npass, " passed, ", nfail, " failed, ", nskip, " skipped"
   if (nfail > 0) error stop 1
end program tester
