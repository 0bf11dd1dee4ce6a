!> A small unit-testing framework in the shape of test-drive (which cannot be fetched here):
!> suites export `collect_<suite>` returning named unit tests; tests receive an
!> `error_type, allocatable` and use `check` with tolerances; `should_fail` marks tests whose
!> error path is expected; `skip_test` reports a skipped test.
!>
!> Usage in a suite:
!>     subroutine collect_sh(tests)
!>        type(unittest_type), allocatable, intent(out) :: tests(:)
!>        tests = [new_unittest("sphere volume", test_sphere_volume)]
!>     end subroutine
!>     subroutine test_sphere_volume(error)
!>        type(error_type), allocatable, intent(out) :: error
!>        call check(error, vol, 4.0_wp/3.0_wp*pi, rel=1.0e-12_wp)
!>     end subroutine
module anm_testing
   use, intrinsic :: iso_fortran_env, only: output_unit
   use anm_core_kinds, only: wp, i8
   use anm_core_error, only: error_type, fatal_error
   use anm_core_strings, only: to_string
   implicit none
   private

   public :: unittest_type, testsuite_type, new_unittest, new_testsuite, check, skip_test, &
      & run_testsuite, test_interface, collect_interface, skip_code, shapes_dir

   !> Error class reserved for skipped tests.
   integer, parameter :: skip_code = 77

   abstract interface
      !> A unit test.
      subroutine test_interface(error)
         import :: error_type
         type(error_type), allocatable, intent(out) :: error
      end subroutine test_interface
   end interface

   !> A named unit test.
   type :: unittest_type
      !> Name.
      character(len=:), allocatable :: name
      !> Test procedure.
      procedure(test_interface), pointer, nopass :: test => null()
      !> The test passes only if it returns an error.
      logical :: should_fail = .false.
   end type unittest_type

   abstract interface
      !> Collect the tests of a suite.
      subroutine collect_interface(tests)
         import :: unittest_type
         type(unittest_type), allocatable, intent(out) :: tests(:)
      end subroutine collect_interface
   end interface

   !> A named suite.
   type :: testsuite_type
      !> Name.
      character(len=:), allocatable :: name
      !> Collector.
      procedure(collect_interface), pointer, nopass :: collect => null()
   end type testsuite_type

   !> Compare actual with expected, allocating `error` on mismatch.
   interface check
      module procedure :: check_logical
      module procedure :: check_int
      module procedure :: check_real
   end interface check

contains

   !> A unit test named `name`.
   function new_unittest(name, test, should_fail) result(ut)
      !> Name.
      character(len=*), intent(in) :: name
      !> Procedure.
      procedure(test_interface) :: test
      !> Expect an error.
      logical, intent(in), optional :: should_fail
      type(unittest_type) :: ut
      ut%name = name
      ut%test => test
      if (present(should_fail)) ut%should_fail = should_fail
   end function new_unittest

   !> A test suite named `name`.
   function new_testsuite(name, collect) result(ts)
      !> Name.
      character(len=*), intent(in) :: name
      !> Collector.
      procedure(collect_interface) :: collect
      type(testsuite_type) :: ts
      ts%name = name
      ts%collect => collect
   end function new_testsuite

   !> Mark the current test as skipped with a reason.
   subroutine skip_test(error, reason)
      !> Error carrying the skip.
      type(error_type), allocatable, intent(out) :: error
      !> Why.
      character(len=*), intent(in) :: reason
      call fatal_error(error, reason, skip_code)
   end subroutine skip_test

   !> Condition must hold.
   subroutine check_logical(error, condition, message)
      !> Error on failure (an earlier failure is kept: checks in a row report the first).
      type(error_type), allocatable, intent(inout) :: error
      !> Condition.
      logical, intent(in) :: condition
      !> Message when it does not hold.
      character(len=*), intent(in), optional :: message
      if (allocated(error)) return
      if (.not. condition) then
         if (present(message)) then
            call fatal_error(error, message)
         else
            call fatal_error(error, "condition not satisfied")
         end if
      end if
   end subroutine check_logical

   !> Integers must be equal.
   subroutine check_int(error, actual, expected, message)
      !> Error on failure (an earlier failure is kept: checks in a row report the first).
      type(error_type), allocatable, intent(inout) :: error
      !> Values.
      integer, intent(in) :: actual, expected
      !> Context.
      character(len=*), intent(in), optional :: message
      if (allocated(error)) return
      if (actual /= expected) then
         call fatal_error(error, ctx(message)//"expected "//to_string(expected)//", got "//to_string(actual))
      end if
   end subroutine check_int

   !> Reals must agree within an absolute (thr) or relative (rel) tolerance (default rel 1e-12).
   subroutine check_real(error, actual, expected, message, thr, rel)
      !> Error on failure (an earlier failure is kept: checks in a row report the first).
      type(error_type), allocatable, intent(inout) :: error
      !> Values.
      real(wp), intent(in) :: actual, expected
      !> Context.
      character(len=*), intent(in), optional :: message
      !> Absolute tolerance.
      real(wp), intent(in), optional :: thr
      !> Relative tolerance.
      real(wp), intent(in), optional :: rel
      logical :: ok
      real(wp) :: diff
      if (allocated(error)) return
      diff = abs(actual - expected)
      if (present(thr)) then
         ok = diff <= thr
      else if (present(rel)) then
         ok = diff <= rel * abs(expected)
      else
         ok = diff <= 1.0e-12_wp * abs(expected)
      end if
      if (actual /= actual) ok = .false.
      if (.not. ok) then
         call fatal_error(error, ctx(message)//"expected "//to_string(expected)//", got " &
                          //to_string(actual)//" (difference "//to_string(diff)//")")
      end if
   end subroutine check_real

   pure function ctx(message) result(str)
      character(len=*), intent(in), optional :: message
      character(len=:), allocatable :: str
      if (present(message)) then
         str = message//": "
      else
         str = ""
      end if
   end function ctx

   !> Run the tests of a suite (only `only_test` when given); count results.
   subroutine run_testsuite(suite, npass, nfail, nskip, only_test)
      !> Suite.
      type(testsuite_type), intent(in) :: suite
      !> Running counts.
      integer, intent(inout) :: npass, nfail, nskip
      !> Run only the test of this name.
      character(len=*), intent(in), optional :: only_test
      type(unittest_type), allocatable :: tests(:)
      type(error_type), allocatable :: error
      integer :: i
      integer(i8) :: t0, t1, rate
      logical :: found

      call suite%collect(tests)
      found = .false.
      do i = 1, size(tests)
         if (present(only_test)) then
            if (tests(i)%name /= only_test) cycle
         end if
         found = .true.
         call system_clock(t0, rate)
         call tests(i)%test(error)
         call system_clock(t1)
         if (allocated(error)) then
            if (error%stat == skip_code) then
               nskip = nskip + 1
               write (output_unit, '(a)') "  SKIP  "//suite%name//" / "//tests(i)%name//": "//error%message
               deallocate (error)
               cycle
            end if
         end if
         if (allocated(error) .neqv. tests(i)%should_fail) then
            nfail = nfail + 1
            if (allocated(error)) then
               write (output_unit, '(a)') "  FAIL  "//suite%name//" / "//tests(i)%name//": "//error%message
            else
               write (output_unit, '(a)') "  FAIL  "//suite%name//" / "//tests(i)%name// &
                  ": expected an error, none was raised"
            end if
         else
            npass = npass + 1
            write (output_unit, '(a,f0.3,a)') "  ok    "//suite%name//" / "//tests(i)%name//" (", &
               real(t1 - t0, wp) / real(rate, wp), " s)"
         end if
         if (allocated(error)) deallocate (error)
      end do
      if (present(only_test) .and. .not. found) then
         nfail = nfail + 1
         write (output_unit, '(a)') "  FAIL  "//suite%name//": no test named '"//only_test//"'"
      end if
   end subroutine run_testsuite

   !> Folder of the real CT shapes: $ANM_SHAPES_DIR or ../shared/shapes. When missing, the test is
   !> skipped, except under CI (CI=true), where it fails.
   subroutine shapes_dir(dir, error)
      !> Folder path.
      character(len=:), allocatable, intent(out) :: dir
      !> Skip or failure when missing.
      type(error_type), allocatable, intent(out) :: error
      character(len=4096) :: buf
      character(len=16) :: ci
      integer :: length, stat
      logical :: exists
      call get_environment_variable("ANM_SHAPES_DIR", buf, length, stat)
      if (stat == 0 .and. length > 0) then
         dir = trim(buf)
      else
         dir = "../shared/shapes"
      end if
      inquire (file=dir//"/MA111-7-coarse/MA111-7-coarse-geom.orig.dat", exist=exists)
      if (.not. exists) then
         call get_environment_variable("CI", ci, length, stat)
         if (stat == 0 .and. (trim(ci) == "true" .or. trim(ci) == "1")) then
            call fatal_error(error, "shape folder "//dir//" is missing (required when CI=true)")
         else
            call skip_test(error, "shape folder "//dir//" is missing")
         end if
      end if
   end subroutine shapes_dir
end module anm_testing
