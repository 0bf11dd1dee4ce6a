!> Tests of the on-disk kind cache (anm_parking_kind_cache, used by anm_parking_kinds): a second
!> kind set reads what the first built and gets the same kinds bit for bit; a corrupt, truncated
!> or foreign entry is rejected and rebuilt; exclusion-shell kinds keep no bare patch arrays.
module test_kind_cache
   use, intrinsic :: iso_fortran_env, only: int8, int64
   use anm_core_kinds, only: wp
   use anm_core_error, only: error_type
   use anm_core_filesystem, only: list_directory, string_type, join_path, make_directory
   use anm_core_output, only: remove_file, temp_name
   use anm_sh_expansion, only: sh_expansion_type
   use anm_shapes_analytic, only: ellipsoid_shape
   use anm_contact_body, only: contact_body_type, new_contact_body
   use anm_config_shells, only: shell_mode
   use anm_shells_thickness, only: thickness_unit
   use anm_parking_kinds, only: particle_kind_type, kind_params_type, kind_set_type, new_kind_set, body_holder
   use anm_testing, only: unittest_type, new_unittest, check
   implicit none
   private
   public :: collect_kind_cache

contains

   !> Tests of this suite.
   subroutine collect_kind_cache(tests)
      type(unittest_type), allocatable, intent(out) :: tests(:)
      tests = [ &
              new_unittest("a second run reads the kinds from the cache, bit for bit the built ones", test_reuse), &
              new_unittest("corrupt, truncated and foreign entries are rejected and rebuilt", test_reject), &
              new_unittest("contact_body_type layout is the one the cache writes", test_layout), &
              new_unittest("support tables come once the attempts pay for them, as new_contact_body's", &
                           test_tables)]
   end subroutine collect_kind_cache

   !> A fresh folder for one test.
   function scratch_dir(name) result(dir)
      character(len=*), intent(in) :: name
      character(len=:), allocatable :: dir
      type(error_type), allocatable :: error
      type(string_type), allocatable :: names(:)
      integer :: i
      dir = temp_name("/tmp/anm-test-kind-cache-"//name)
      call make_directory(dir, error)
      call list_directory(dir, names, error)
      if (allocated(names)) then
         do i = 1, size(names)
            call remove_file(join_path(dir, names(i)%s))
         end do
      end if
   end function scratch_dir

   !> Remove a test's folder (under /tmp, made by scratch_dir) and its entries.
   subroutine remove_dir(dir)
      character(len=*), intent(in) :: dir
      integer :: stat
      if (index(dir, "/tmp/anm-test-kind-cache-") /= 1) return
      call execute_command_line("rm -rf '"//dir//"'", exitstat=stat)
   end subroutine remove_dir

   !> Two ellipsoids, one sieve, shells of 0.05 mm (two width levels drawn): the kinds to build.
   subroutine setup(ks, kinds, dir)
      type(kind_set_type), intent(out) :: ks
      type(particle_kind_type), allocatable, intent(out) :: kinds(:)
      character(len=*), intent(in) :: dir
      type(kind_params_type) :: p
      type(sh_expansion_type) :: shapes(2)
      character(len=8) :: names(2)
      shapes(1) = ellipsoid_shape(1.0_wp, 0.8_wp, 0.6_wp, 6)
      shapes(2) = ellipsoid_shape(1.0_wp, 0.7_wp, 0.7_wp, 6)
      names = ["e1", "e2"]
      p%file = "test"
      p%nlayer = 1
      p%thickness = [0.05_wp]
      p%unit = thickness_unit%mm
      p%mode = shell_mode%exclude
      p%min_width = [1.0_wp]
      p%max_width = [1.4_wp]
      p%cache_directory = dir
      call new_kind_set(ks, kinds, p, shapes, names, [0], [2], [6])
   end subroutine setup

   !> Kinds 1 (level 1 of shape 1) and 4 (level 2 of shape 2), with their shell layers.
   subroutine build_some(ks, kinds, error)
      type(kind_set_type), intent(inout) :: ks
      type(particle_kind_type), intent(inout) :: kinds(:)
      type(error_type), allocatable, intent(out) :: error
      call ks%build(kinds, [1, 4], error)
      if (allocated(error)) return
      call check(error, .not. (allocated(kinds(1)%layers) .or. allocated(kinds(4)%layers)) .and. kinds(1)%gap > 0.0_wp, &
                 "built kinds have their gap, not yet their layers")
      if (allocated(error)) return
      call ks%build_layers(kinds, [1, 4], error)
   end subroutine build_some

   !> Whether two kinds hold the same data, bit for bit.
   logical function same_kind(a, b) result(same)
      type(particle_kind_type), intent(in) :: a, b
      same = a%width == b%width .and. a%length == b%length .and. a%volume == b%volume .and. a%r_out == b%r_out &
             .and. a%r_in_query == b%r_in_query .and. a%r_in_parked == b%r_in_parked
      same = same .and. same_body(a%body, b%body)
      same = same .and. a%gap == b%gap
      same = same .and. allocated(a%layers) .eqv. allocated(b%layers)
      if (allocated(a%layers) .and. allocated(b%layers)) then
         same = same .and. size(a%layers) == size(b%layers) .and. all(a%layer_volume == b%layer_volume)
         if (same) same = same_expansion(a%layers(1), b%layers(1))
      end if
   end function same_kind

   logical function same_expansion(a, b) result(same)
      type(sh_expansion_type), intent(in) :: a, b
      same = a%nmax == b%nmax
      if (same) same = all(a%a == b%a) .and. all(a%b == b%b)
   end function same_expansion

   logical function same_body(a, b) result(same)
      type(contact_body_type), intent(in) :: a, b
      same = a%nmax == b%nmax .and. a%next == b%next .and. a%r_max == b%r_max .and. a%r_min == b%r_min &
             .and. a%lipschitz == b%lipschitz .and. a%curvature == b%curvature .and. a%third == b%third &
             .and. all(a%box_lo == b%box_lo) .and. all(a%box_hi == b%box_hi) .and. all(a%ext_lo == b%ext_lo) &
             .and. all(a%ext_hi == b%ext_hi) .and. all(a%off == b%off) .and. all(a%doff == b%doff) &
             .and. all(a%roff == b%roff) .and. all(a%coff == b%coff)
      same = same .and. same_expansion(a%shape, b%shape)
      same = same .and. (allocated(a%node) .eqv. allocated(b%node))
      if (.not. (same .and. allocated(a%node))) return
      same = all(a%dir == b%dir) .and. all(a%cosa == b%cosa) .and. all(a%sina == b%sina) .and. all(a%rlo == b%rlo) &
             .and. all(a%rhi == b%rhi) .and. all(a%ball == b%ball) .and. all(a%brad == b%brad) &
             .and. all(a%dlo == b%dlo) .and. all(a%dhi == b%dhi) .and. all(a%row_ct == b%row_ct) &
             .and. all(a%row_st == b%row_st) .and. all(a%row_cosa == b%row_cosa) .and. all(a%row_sina == b%row_sina) &
             .and. all(a%col_cp == b%col_cp) .and. all(a%col_sp == b%col_sp) .and. all(a%node == b%node)
      ! support tables are built after the kinds, as their use pays (never cached)
      same = same .and. (allocated(a%supp) .eqv. allocated(b%supp))
      if (same .and. allocated(a%supp)) same = all(a%supp == b%supp)
   end function same_body

   subroutine test_reuse(error)
      type(error_type), allocatable, intent(out) :: error
      type(kind_set_type) :: ks1, ks2
      type(particle_kind_type), allocatable :: k1(:), k2(:)
      character(len=:), allocatable :: dir
      integer :: i
      dir = scratch_dir("reuse")
      call setup(ks1, k1, dir)
      call build_some(ks1, k1, error)
      if (allocated(error)) return
      call check(error, ks1%cache%on .and. ks1%cache%written == 4 .and. ks1%cache%hits == 0 .and. &
                 ks1%bases_built == 2 .and. ks1%shells_built == 2, "first run: 2 bases and 2 shells built and written")
      if (allocated(error)) return
      call setup(ks2, k2, dir)
      call build_some(ks2, k2, error)
      if (allocated(error)) return
      call check(error, ks2%cache%hits == 4 .and. ks2%cache%written == 0 .and. ks2%bases_built == 0 .and. &
                 ks2%shells_built == 0, "second run: everything read from the cache, nothing built")
      if (allocated(error)) return
      do i = 1, 4, 3
         call check(error, same_kind(k1(i), k2(i)), "kind built = kind read")
         if (allocated(error)) return
         call check(error, allocated(k2(i)%body%node) .and. k2(i)%gap > 0.0_wp, &
                    "exclusion shells: the bare body's patch arrays and a gap (no shell contact body)")
         if (allocated(error)) return
      end do
      call remove_dir(dir)
   end subroutine test_reuse

   subroutine test_reject(error)
      type(error_type), allocatable, intent(out) :: error
      type(kind_set_type) :: ks0, ks1, ks3
      type(particle_kind_type), allocatable :: k0(:), k1(:), k3(:)
      type(string_type), allocatable :: names(:)
      character(len=:), allocatable :: dir
      integer(int8), allocatable :: bytes(:)
      integer :: i, unit, n, big, small
      integer(int64) :: sz, szmax, szmin
      dir = scratch_dir("reject")
      call setup(ks0, k0, dir)
      call build_some(ks0, k0, error)
      if (allocated(error)) return
      call list_directory(dir, names, error)
      if (allocated(error)) return
      call check(error, size(names) == 4, "four entries")
      if (allocated(error)) return
      ! damage: one byte flipped in the largest entry, the smallest truncated, and one entry
      ! replaced by another's content (a foreign key under its name)
      szmax = -1
      szmin = huge(1_int64)
      do i = 1, size(names)
         inquire (file=join_path(dir, names(i)%s), size=sz)
         if (sz > szmax) then
            szmax = sz
            big = i
         end if
         if (sz < szmin) then
            szmin = sz
            small = i
         end if
      end do
      call read_bytes(join_path(dir, names(big)%s), bytes)
      n = size(bytes)
      bytes(n - 100) = not(bytes(n - 100))
      call write_bytes(join_path(dir, names(big)%s), bytes)
      call read_bytes(join_path(dir, names(small)%s), bytes)
      call write_bytes(join_path(dir, names(small)%s), bytes(:size(bytes) - 8))
      do i = 1, size(names)
         if (i /= big .and. i /= small) exit
      end do
      call write_bytes(join_path(dir, names(i)%s), bytes)
      call setup(ks1, k1, dir)
      call build_some(ks1, k1, error)
      if (allocated(error)) return
      call check(error, ks1%cache%rejected == 3 .and. ks1%cache%hits == 1 .and. ks1%cache%written == 3, &
                 "three damaged entries rejected (and rewritten), one read")
      if (allocated(error)) return
      do i = 1, 4, 3
         call check(error, same_kind(k0(i), k1(i)), "kinds after rejections = the kinds first built")
         if (allocated(error)) return
      end do
      call setup(ks3, k3, dir)
      call build_some(ks3, k3, error)
      if (allocated(error)) return
      call check(error, ks3%cache%hits == 4 .and. ks3%cache%rejected == 0, "the rewritten entries are read")
      if (allocated(error)) return
      ! a garbage file under an entry's name
      open (newunit=unit, file=join_path(dir, names(1)%s), status="replace", action="write")
      write (unit, '(a)') "not a kind cache entry"
      close (unit)
      call setup(ks3, k3, dir)
      call build_some(ks3, k3, error)
      if (allocated(error)) return
      call check(error, ks3%cache%hits == 3 .and. ks3%cache%rejected == 1, "a text file is rejected")
      call remove_dir(dir)
   end subroutine test_reject

   !> Kinds are built without support tables (and the cache holds none); add_tables gives the
   !> bodies the contact test uses (the bare bodies: exclusion shells are a gap around them) their
   !> tables once the run has made 5,000 attempts per body without one, or at once with `now`; the
   !> tables are those new_contact_body builds, and a kind built later from a base that has its
   !> table has it too.
   subroutine test_tables(error)
      type(error_type), allocatable, intent(out) :: error
      type(kind_set_type) :: ks
      type(particle_kind_type), allocatable :: kinds(:)
      type(contact_body_type) :: ref
      character(len=:), allocatable :: dir
      dir = scratch_dir("tables")
      call setup(ks, kinds, dir)
      call build_some(ks, kinds, error)
      if (allocated(error)) return
      call check(error, .not. (allocated(kinds(1)%body%supp) .or. allocated(kinds(4)%body%supp)), &
                 "kinds built without tables")
      if (allocated(error)) return
      call ks%add_tables(kinds, 9999_int64)
      call check(error, .not. allocated(kinds(1)%body%supp) .and. ks%tables_built == 0, &
                 "no tables before 5,000 attempts per body (2 bodies, 9,999 attempts)")
      if (allocated(error)) return
      call ks%add_tables(kinds, 10000_int64)
      call check(error, allocated(kinds(1)%body%supp) .and. allocated(kinds(4)%body%supp) .and. ks%tables_built == 2, &
                 "tables for the two bodies at 10,000 attempts")
      if (allocated(error)) return
      call new_contact_body(ref, kinds(4)%body%shape, error)
      if (allocated(error)) return
      call check(error, all(ref%supp == kinds(4)%body%supp), "the table is new_contact_body's")
      if (allocated(error)) return
      ! kind 2: shape 2 at the other width level, sharing the bare body of kind 4 (no copy)
      call ks%build(kinds, [2], error)
      if (allocated(error)) return
      call check(error, body_holder(kinds, 2) == 4 .and. .not. allocated(kinds(2)%body%node) .and. &
                 body_holder(kinds, 4) == 4, "a kind of another width level shares its base's body")
      if (allocated(error)) return
      call check(error, allocated(kinds(body_holder(kinds, 2))%body%supp), &
                 "a kind built from a base with its table has the table")
      if (allocated(error)) return
      call ks%add_tables(kinds, 10001_int64, now=.true.)
      call check(error, ks%tables_built == 2, "now: nothing left to build")
      call remove_dir(dir)
   end subroutine test_tables

   subroutine test_layout(error)
      type(error_type), allocatable, intent(out) :: error
      type(contact_body_type) :: body
      ! a new component of contact_body_type must be written by put_body/get_body
      ! (src/parking/kind_cache.f90) and compared in same_body above; then update this size and
      ! bump cache_format_version (exceptions: the support table `supp`, built later and never
      ! cached, and the expansion's Legendre table, rebuilt from the coefficients)
      call check(error, storage_size(body), 16064, "storage_size(contact_body_type) (bits)")
   end subroutine test_layout

   subroutine read_bytes(path, bytes)
      character(len=*), intent(in) :: path
      integer(int8), allocatable, intent(out) :: bytes(:)
      integer :: unit
      integer(int64) :: sz
      inquire (file=path, size=sz)
      allocate (bytes(sz))
      open (newunit=unit, file=path, access="stream", form="unformatted", status="old", action="read")
      read (unit) bytes
      close (unit)
   end subroutine read_bytes

   subroutine write_bytes(path, bytes)
      character(len=*), intent(in) :: path
      integer(int8), intent(in) :: bytes(:)
      integer :: unit
      open (newunit=unit, file=path, access="stream", form="unformatted", status="replace", action="write")
      write (unit) bytes
      close (unit)
   end subroutine write_bytes
end module test_kind_cache
