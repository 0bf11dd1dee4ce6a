!> Tests of the packing type: add, remove and move keep the neighbour query and the overlap test of
!> a candidate pose equal to brute force (spheres, whose overlap is known exactly), in periodic
!> and walled boxes; a mark limits the test to the particles placed after it; reserving room and
!> growing past it keep every particle.
module test_packing
   use anm_core_kinds, only: wp, i8
   use anm_core_error, only: error_type
   use anm_core_random, only: rng_type, new_rng
   use anm_shapes_analytic, only: sphere_shape, ellipsoid_shape
   use anm_contact_body, only: contact_body_type
   use anm_parking_void_grid, only: void_grid_type, new_void_grid
   use anm_geometry_rotation, only: random_rotation
   use anm_contact_body, only: new_contact_body
   use anm_parking_kinds, only: particle_kind_type
   use anm_parking_packing, only: packing_type, packing_params_type, fit_scratch_type, new_packing, near_slab
   use anm_testing, only: unittest_type, new_unittest, check
   implicit none
   private
   public :: collect_packing

   !> Candidates closer than this (relative) to contact are not judged (the exact test's tolerance).
   real(wp), parameter :: contact_margin = 1.0e-6_wp

contains

   !> Tests of this suite.
   subroutine collect_packing(tests)
      type(unittest_type), allocatable, intent(out) :: tests(:)
      tests = [ &
              new_unittest("add/remove/move: neighbours = brute force, periodic", test_neighbours_periodic), &
              new_unittest("add/remove/move: neighbours = brute force, walls", test_neighbours_walls), &
              new_unittest("add/remove/move: fits (with and without a hint) = sphere overlap, periodic", &
                           test_fits_periodic), &
              new_unittest("add/remove/move: fits (with and without a hint) = sphere overlap and walls", &
                           test_fits_walls), &
              new_unittest("compact keeps the particles and the answers", test_compact), &
              new_unittest("fits since a mark tests only later particles", test_since), &
              new_unittest("void grid: certified-bounds blocking = exact blocking", test_void_bounds), &
              new_unittest("reserve and growth keep the particles and the answers", test_reserve), &
              new_unittest("slabs: a slab's local packing answers as the whole one, periodic", test_slabs_periodic), &
              new_unittest("slabs: a slab's local packing answers as the whole one, walls", test_slabs_walls), &
              new_unittest("slabs: uneven slabs moved while parking answer as the whole packing", test_slabs_moved), &
              new_unittest("divided arrays: three slabs' arrays, exchanged on a grown reach and moved slabs, "// &
                           "answer as the whole packing and hold every particle once", test_divided)]
   end subroutine collect_packing

   !> A packing of unit-sphere kinds (kind 1) with periodic or walled box (slab `slab` of `nslab`).
   subroutine sphere_packing(pk, periodic, box, error, nslab, slab, divided)
      type(packing_type), intent(out) :: pk
      logical, intent(in) :: periodic
      real(wp), intent(in) :: box(3)
      type(error_type), allocatable, intent(out) :: error
      integer, intent(in), optional :: nslab, slab
      logical, intent(in), optional :: divided
      type(particle_kind_type), allocatable :: kinds(:)
      type(packing_params_type) :: p
      allocate (kinds(1))
      call new_contact_body(kinds(1)%body, sphere_shape(1.0_wp), error)
      if (allocated(error)) return
      kinds(1)%width = 2.0_wp
      kinds(1)%volume = 4.0_wp / 3.0_wp * acos(-1.0_wp)
      kinds(1)%r_out = kinds(1)%body%r_max
      kinds(1)%r_in_query = kinds(1)%body%r_min
      kinds(1)%r_in_parked = kinds(1)%body%r_min
      p%box = box
      p%periodic = periodic
      p%rho_min = 0.1_wp
      if (present(nslab)) p%nslab = nslab
      if (present(slab)) p%slab = slab
      if (present(divided)) p%divided = divided
      call new_packing(pk, p, kinds)
   end subroutine sphere_packing

   !> Random adds (radii 0.1..1, log-uniform), then removes and moves (with new scales).
   subroutine shuffle(pk, rng, n, nremove, nmove)
      type(packing_type), intent(inout) :: pk
      type(rng_type), intent(inout) :: rng
      integer, intent(in) :: n, nremove, nmove
      integer :: i
      do i = 1, n
         call pk%add(1, [rng%uniform(), rng%uniform(), rng%uniform()] * pk%p%box, random_rotation(rng), &
                     0.1_wp * 10.0_wp**rng%uniform(), 1)
      end do
      do i = 1, nremove
         call pk%remove(rng%below(pk%np))
      end do
      do i = 1, nmove
         call pk%move(rng%below(pk%np), [rng%uniform(), rng%uniform(), rng%uniform()] * pk%p%box, &
                      random_rotation(rng), 0.1_wp * 10.0_wp**rng%uniform())
      end do
   end subroutine shuffle

   !> Nearest-image distance between two points.
   pure real(wp) function distance(pk, a, b) result(d)
      type(packing_type), intent(in) :: pk
      real(wp), intent(in) :: a(3), b(3)
      real(wp) :: e(3)
      e = a - b
      if (pk%p%periodic) e = e - pk%p%box * anint(e / pk%p%box)
      d = norm2(e)
   end function distance

   subroutine neighbours_case(error, periodic)
      type(error_type), allocatable, intent(out) :: error
      logical, intent(in) :: periodic
      type(packing_type) :: pk
      type(rng_type) :: rng
      integer, allocatable :: ids(:)
      real(wp), allocatable :: shifts(:, :)
      real(wp) :: q(3), rq
      integer :: k, n, j, nbrute
      logical, allocatable :: seen(:)
      call sphere_packing(pk, periodic, [10.0_wp, 10.0_wp, 10.0_wp], error)
      if (allocated(error)) return
      call new_rng(rng, 21_i8, 0_i8)
      call shuffle(pk, rng, 400, 150, 200)
      call check(error, pk%np, 250, "particles after 400 adds and 150 removes")
      if (allocated(error)) return
      do k = 1, 200
         q = [rng%uniform(), rng%uniform(), rng%uniform()] * pk%p%box
         rq = 0.1_wp * 10.0_wp**rng%uniform()
         call pk%neighbours(q, rq, ids, shifts, n)
         allocate (seen(pk%np))
         seen = .false.
         seen(ids(:n)) = .true.
         nbrute = 0
         do j = 1, pk%np
            if (distance(pk, pk%center(:, j), q) < rq + pk%rho(j)) nbrute = nbrute + 1
         end do
         call check(error, n, nbrute, "neighbours vs brute force")
         if (allocated(error)) return
         do j = 1, n
            call check(error, norm2(pk%center(:, ids(j)) + shifts(:, j) - q) < rq + pk%rho(ids(j)), &
                       "a neighbour's image meets the sphere")
            if (allocated(error)) return
         end do
         deallocate (seen)
      end do
   end subroutine neighbours_case

   subroutine test_neighbours_periodic(error)
      type(error_type), allocatable, intent(out) :: error
      call neighbours_case(error, .true.)
   end subroutine test_neighbours_periodic

   subroutine test_neighbours_walls(error)
      type(error_type), allocatable, intent(out) :: error
      call neighbours_case(error, .false.)
   end subroutine test_neighbours_walls

   !> Brute-force answer for a candidate sphere (x, r): 1 fits, 0 overlaps, -1 too close to call.
   integer function brute_fit(pk, x, r, walls) result(ans)
      type(packing_type), intent(in) :: pk
      real(wp), intent(in) :: x(3), r
      logical, intent(in) :: walls
      integer :: j
      real(wp) :: gap
      ans = 1
      if (walls) then
         gap = min(minval(x), minval(pk%p%box - x)) - r
         if (abs(gap) < contact_margin * r) then
            ans = -1
            return
         end if
         if (gap < 0.0_wp) ans = 0
      end if
      do j = 1, pk%np
         gap = distance(pk, pk%center(:, j), x) - r - pk%scale(j)
         if (abs(gap) < contact_margin * (r + pk%scale(j))) then
            ans = -1
            return
         end if
         if (gap < 0.0_wp) ans = 0
      end do
   end function brute_fit

   subroutine fits_case(error, periodic, compact)
      type(error_type), allocatable, intent(out) :: error
      logical, intent(in) :: periodic, compact
      type(packing_type) :: pk
      type(rng_type) :: rng
      type(fit_scratch_type) :: scratch
      real(wp) :: x(3), r, rot(3, 3)
      integer :: k, ans, nfit, nover, by, nby
      call sphere_packing(pk, periodic, [8.0_wp, 8.0_wp, 8.0_wp], error)
      if (allocated(error)) return
      call new_rng(rng, 23_i8, 0_i8)
      call shuffle(pk, rng, 120, 40, 60)
      if (compact) then
         call pk%compact()
         call check(error, pk%ndead, 0, "no retired records after compact")
         if (allocated(error)) return
      end if
      nfit = 0
      nover = 0
      nby = 0
      do k = 1, 400
         x = [rng%uniform(), rng%uniform(), rng%uniform()] * pk%p%box
         r = 0.1_wp * 10.0_wp**rng%uniform()
         ans = brute_fit(pk, x, r, .not. periodic)
         if (ans < 0) cycle
         if (ans == 1) nfit = nfit + 1
         if (ans == 0) nover = nover + 1
         rot = random_rotation(rng)
         call check(error, pk%fits(1, x, rot, r, scratch) .eqv. (ans == 1), &
                    "fits disagrees with the sphere overlap")
         if (allocated(error)) return
         ! a hint (any particle, tested first) changes no answer; the particle named as the
         ! refuser does overlap the candidate
         call check(error, pk%fits(1, x, rot, r, scratch, hint=1 + mod(k * 7, pk%np), blocker=by) .eqv. &
                    (ans == 1), "fits with a hint disagrees with the sphere overlap")
         if (allocated(error)) return
         if (by > 0) then
            nby = nby + 1
            call check(error, distance(pk, pk%center(:, by), x) < r + pk%scale(by), &
                       "the particle named as refuser does not overlap the candidate")
            if (allocated(error)) return
         end if
      end do
      call check(error, nfit > 20 .and. nover > 20, "both answers were tested")
      if (allocated(error)) return
      ! after compact the cell list proves a sphere's overlap by itself (no pair test, no refuser)
      if (.not. compact) call check(error, nby > 20, "refusers were named")
   end subroutine fits_case

   !> Slabs (the MPI build's spatial decomposition): for each slab of 3 along x, particles are added
   !> in batches with `localize` after each (and the reach grown once, which rebuilds the cell
   !> list); then every candidate centred in the slab with a bounding radius within the reach fits
   !> exactly when it overlaps none of all the particles (brute force over the whole packing),
   !> while the slab's cell list holds fewer particles than the packing.
   subroutine slabs_case(error, periodic, moved)
      type(error_type), allocatable, intent(out) :: error
      logical, intent(in) :: periodic
      !> Uneven slab bounds, set after the third batch (`set_slab`, which rebuilds the cell list).
      logical, intent(in), optional :: moved
      type(packing_type) :: pk
      type(rng_type) :: rng
      type(fit_scratch_type) :: scratch
      real(wp) :: x(3), r, lx, lo, hi
      real(wp), parameter :: uneven(0:3) = [0.0_wp, 2.5_wp, 8.0_wp, 12.0_wp]
      integer :: slab, batch, i, k, ans, nfit, nover, first, nlocal, noutside
      lx = 12.0_wp
      do slab = 0, 2
         call sphere_packing(pk, periodic, [lx, 6.0_wp, 6.0_wp], error, nslab=3, slab=slab)
         if (allocated(error)) return
         call new_rng(rng, 31_i8, int(slab, i8))
         call pk%set_reach(0.3_wp)
         do batch = 1, 8
            ! the reach grows once: the cell list is rebuilt with the wider halo
            if (batch == 5) call pk%set_reach(0.6_wp)
            if (present(moved) .and. batch == 4) then
               if (moved) call pk%set_slab(uneven(slab), uneven(slab + 1))
            end if
            first = pk%np + 1
            do i = 1, 25
               call pk%add(1, [rng%uniform() * lx, rng%uniform() * 6.0_wp, rng%uniform() * 6.0_wp], &
                           random_rotation(rng), 0.05_wp + 0.25_wp * rng%uniform(), 1)
            end do
            call pk%localize(first)
         end do
         nlocal = count(pk%record(:pk%np) > 0)
         call check(error, nlocal > 0 .and. nlocal < pk%np, "the slab holds part of the particles")
         if (allocated(error)) return
         nfit = 0
         nover = 0
         noutside = 0
         call pk%slab_bounds(lo, hi)
         do k = 1, 2000
            ! centres near the slab's faces, where the halo matters
            x = [merge(lo, hi, k <= 1000) + merge(1.0_wp, -1.0_wp, k <= 1000) * 0.7_wp * rng%uniform(), &
                 rng%uniform() * 6.0_wp, rng%uniform() * 6.0_wp]
            if (.not. pk%owns(x)) cycle
            r = 0.6_wp * rng%uniform()
            ans = brute_fit(pk, x, r, .not. periodic)
            if (ans < 0) cycle
            if (ans == 1) nfit = nfit + 1
            if (ans == 0) nover = nover + 1
            if (ans == 0 .and. only_outside(pk, x, r, lo, hi)) noutside = noutside + 1
            call check(error, pk%fits(1, x, random_rotation(rng), r, scratch) .eqv. (ans == 1), &
                       "a slab's fits disagrees with the whole packing")
            if (allocated(error)) return
         end do
         call check(error, nfit > 20 .and. nover > 20, "both answers were tested")
         if (allocated(error)) return
         call check(error, noutside > 20, "candidates overlapping only particles centred outside the slab were tested")
         if (allocated(error)) return
      end do
   end subroutine slabs_case

   !> Whether every particle that the sphere (x, r) overlaps has its centre outside [lo, hi) along x.
   logical function only_outside(pk, x, r, lo, hi) result(yes)
      type(packing_type), intent(in) :: pk
      real(wp), intent(in) :: x(3), r, lo, hi
      integer :: j
      yes = .true.
      do j = 1, pk%np
         if (distance(pk, pk%center(:, j), x) >= r + pk%scale(j)) cycle
         if (pk%center(1, j) >= lo .and. pk%center(1, j) < hi) then
            yes = .false.
            return
         end if
      end do
   end function only_outside

   !> Divided arrays (the MPI build's, three processes emulated here): the same particles are added
   !> in the same order to a whole packing and to the three slabs' divided packings, each
   !> localized after every batch (its arrays then hold only its slab and halo). The reach grows
   !> beyond what the arrays hold once and the slabs move once: both times each slab's owned
   !> particles within the new reach of another slab go to it (`take_particles`, as the MPI
   !> exchange sends them). Then each slab's fits answers as brute force over the whole packing
   !> for candidates centred in it, its arrays hold fewer particles than all, in ascending global
   !> ids, and the particles the slabs own are every particle once, with its pose.
   subroutine divided_case(error, periodic)
      type(error_type), allocatable, intent(out) :: error
      logical, intent(in) :: periodic
      type(packing_type) :: whole, pk(0:2)
      type(rng_type) :: rng
      type(fit_scratch_type) :: scratch
      real(wp) :: x(3), r, lo, hi, box(3), rr(3, 3), sc
      real(wp), parameter :: uneven(0:3) = [0.0_wp, 2.5_wp, 8.0_wp, 12.0_wp]
      integer :: q, batch, i, k, ans, nfit, nover
      integer, allocatable :: seen(:)
      box = [12.0_wp, 6.0_wp, 6.0_wp]
      call sphere_packing(whole, periodic, box, error)
      if (allocated(error)) return
      do q = 0, 2
         call sphere_packing(pk(q), periodic, box, error, nslab=3, slab=q, divided=.true.)
         if (allocated(error)) return
         call pk(q)%set_reach(0.3_wp)
      end do
      call new_rng(rng, 37_i8, 1_i8)
      do batch = 1, 8
         if (batch == 4) call exchange(pk, uneven, 0.3_wp)
         if (batch == 6) then
            ! a reach beyond what the arrays hold: the other slabs' particles first
            call check(error, 0.6_wp > pk(0)%held_reach, "the arrays hold less than the new reach needs")
            if (allocated(error)) return
            call exchange(pk, uneven, 0.6_wp)
         end if
         do i = 1, 30
            x = [rng%uniform() * box(1), rng%uniform() * box(2), rng%uniform() * box(3)]
            rr = random_rotation(rng)
            sc = 0.05_wp + 0.25_wp * rng%uniform()
            call whole%add(1, x, rr, sc, 1)
            do q = 0, 2
               call pk(q)%add(1, x, rr, sc, 1)
            end do
         end do
         do q = 0, 2
            call pk(q)%localize(pk(q)%np - 29)
         end do
      end do
      allocate (seen(whole%np))
      seen = 0
      do q = 0, 2
         call check(error, pk(q)%np < whole%np .and. pk(q)%ntotal == whole%np, "a slab's arrays hold part of the particles")
         if (allocated(error)) return
         call check(error, all(pk(q)%gid(2:pk(q)%np) > pk(q)%gid(:pk(q)%np - 1)), "global ids ascending")
         if (allocated(error)) return
         do i = 1, pk(q)%np
            if (.not. pk(q)%owns(pk(q)%center(:, i))) cycle
            k = pk(q)%gid(i)
            seen(k) = seen(k) + 1
            call check(error, all(pk(q)%center(:, i) == whole%center(:, k)) .and. pk(q)%scale(i) == whole%scale(k) .and. &
                       all(pk(q)%rot(:, :, i) == whole%rot(:, :, k)), "an owned particle has its pose")
            if (allocated(error)) return
         end do
         nfit = 0
         nover = 0
         call pk(q)%slab_bounds(lo, hi)
         do k = 1, 2000
            x = [merge(lo, hi, k <= 1000) + merge(1.0_wp, -1.0_wp, k <= 1000) * 0.7_wp * rng%uniform(), &
                 rng%uniform() * box(2), rng%uniform() * box(3)]
            if (.not. pk(q)%owns(x)) cycle
            r = 0.6_wp * rng%uniform()
            ans = brute_fit(whole, x, r, .not. periodic)
            if (ans < 0) cycle
            if (ans == 1) nfit = nfit + 1
            if (ans == 0) nover = nover + 1
            call check(error, pk(q)%fits(1, x, random_rotation(rng), r, scratch) .eqv. (ans == 1), &
                       "a slab's divided arrays answer otherwise than the whole packing")
            if (allocated(error)) return
         end do
         call check(error, nfit > 20 .and. nover > 20, "both answers were tested")
         if (allocated(error)) return
      end do
      call check(error, all(seen == 1), "every particle owned once")
   contains
      !> The MPI exchange, emulated: the slabs' owned particles within reach of the other slabs'
      !> new bounds go to them; then every slab takes its new bounds and reach and what it got.
      subroutine exchange(pk, nb, reach)
         type(packing_type), intent(inout) :: pk(0:2)
         real(wp), intent(in) :: nb(0:3), reach
         integer :: q, o, j, n
         integer, allocatable :: g(:), kn(:), sv(:)
         real(wp), allocatable :: c(:, :), rt(:, :, :), s(:)
         type(packing_type) :: before(0:2)
         before = pk
         do q = 0, 2
            allocate (g(0), kn(0), sv(0), c(3, 0), rt(3, 3, 0), s(0))
            do o = 0, 2
               if (o == q) cycle
               do j = 1, before(o)%np
                  if (.not. before(o)%owns(before(o)%center(:, j))) cycle
                  if (.not. near_slab(before(o)%p, nb(q), nb(q + 1), q, reach, before(o)%center(1, j), &
                                      before(o)%rho(j))) cycle
                  g = [g, before(o)%gid(j)]
                  kn = [kn, before(o)%kind_of(j)]
                  sv = [sv, before(o)%sieve(j)]
                  s = [s, before(o)%scale(j)]
                  n = size(g)
                  c = reshape([reshape(c, [3 * (n - 1)]), before(o)%center(:, j)], [3, n])
                  rt = reshape([reshape(rt, [9 * (n - 1)]), reshape(before(o)%rot(:, :, j), [9])], [3, 3, n])
               end do
            end do
            pk(q)%slab_lo = nb(q)
            pk(q)%slab_hi = nb(q + 1)
            pk(q)%reach = reach
            call pk(q)%take_particles(g, c, rt, s, kn, sv)
            deallocate (g, kn, sv, c, rt, s)
         end do
      end subroutine exchange
   end subroutine divided_case

   subroutine test_divided(error)
      type(error_type), allocatable, intent(out) :: error
      call divided_case(error, .true.)
      if (allocated(error)) return
      call divided_case(error, .false.)
   end subroutine test_divided

   subroutine test_slabs_periodic(error)
      type(error_type), allocatable, intent(out) :: error
      call slabs_case(error, .true.)
   end subroutine test_slabs_periodic

   subroutine test_slabs_walls(error)
      type(error_type), allocatable, intent(out) :: error
      call slabs_case(error, .false.)
   end subroutine test_slabs_walls

   subroutine test_slabs_moved(error)
      type(error_type), allocatable, intent(out) :: error
      call slabs_case(error, .true., moved=.true.)
      if (allocated(error)) return
      call slabs_case(error, .false., moved=.true.)
   end subroutine test_slabs_moved

   subroutine test_fits_periodic(error)
      type(error_type), allocatable, intent(out) :: error
      call fits_case(error, .true., .false.)
   end subroutine test_fits_periodic

   subroutine test_fits_walls(error)
      type(error_type), allocatable, intent(out) :: error
      call fits_case(error, .false., .false.)
   end subroutine test_fits_walls

   subroutine test_compact(error)
      type(error_type), allocatable, intent(out) :: error
      call fits_case(error, .true., .true.)
   end subroutine test_compact

   subroutine test_since(error)
      type(error_type), allocatable, intent(out) :: error
      type(packing_type) :: pk
      type(fit_scratch_type) :: scratch
      real(wp) :: rot(3, 3)
      integer :: m
      rot = reshape([1.0_wp, 0.0_wp, 0.0_wp, 0.0_wp, 1.0_wp, 0.0_wp, 0.0_wp, 0.0_wp, 1.0_wp], [3, 3])
      call sphere_packing(pk, .true., [10.0_wp, 10.0_wp, 10.0_wp], error)
      if (allocated(error)) return
      call pk%add(1, [2.0_wp, 2.0_wp, 2.0_wp], rot, 1.0_wp, 1)
      call pk%add(1, [6.0_wp, 6.0_wp, 6.0_wp], rot, 1.0_wp, 1)
      m = pk%mark()
      call check(error, .not. pk%fits(1, [2.5_wp, 2.0_wp, 2.0_wp], rot, 1.0_wp, scratch), "overlap with particle 1")
      if (allocated(error)) return
      call check(error, pk%fits(1, [2.5_wp, 2.0_wp, 2.0_wp], rot, 1.0_wp, scratch, since=m), "nothing placed since the mark")
      if (allocated(error)) return
      ! particle 2 moves next to the candidate: after the mark
      call pk%move(2, [3.0_wp, 4.0_wp, 2.0_wp], rot)
      call check(error, .not. pk%fits(1, [2.5_wp, 3.0_wp, 2.0_wp], rot, 0.5_wp, scratch, since=m), &
                 "the moved particle counts after the mark")
      if (allocated(error)) return
      call pk%remove(2)
      call check(error, pk%fits(1, [2.5_wp, 3.0_wp, 2.0_wp], rot, 0.5_wp, scratch, since=m), &
                 "the removed particle is gone")
   end subroutine test_since

   !> The void grid blocks the same cells whether a cell is decided by the contact body's certified
   !> patch bounds first (the fast path) or by evaluating r at every cell (brute force): elongated
   !> ellipsoids at order 14 in random poses, periodic and walled boxes, an inscribed radius for
   !> which the radial offset is used (r_in above the cell half-diagonal).
   subroutine test_void_bounds(error)
      type(error_type), allocatable, intent(out) :: error
      type(contact_body_type) :: body
      type(void_grid_type) :: fast, slow
      type(rng_type) :: rng
      real(wp) :: box(3), rr(3, 3), x(3), sc
      integer :: i, iper, nb
      logical :: periodic
      call new_contact_body(body, ellipsoid_shape(1.0_wp, 0.55_wp, 0.3_wp, 14), error)
      if (allocated(error)) return
      call new_rng(rng, 7_i8, 0_i8)
      box = [6.0_wp, 5.0_wp, 4.0_wp]
      do iper = 1, 2
         periodic = iper == 1
         call new_void_grid(fast, box, periodic, 0.2_wp, 200000)
         call new_void_grid(slow, box, periodic, 0.2_wp, 200000)
         call check(error, 0.5_wp * norm2(fast%h) < 0.2_wp, "the offset test is used (cells finer than r_in)")
         if (allocated(error)) return
         do i = 1, 12
            x = [rng%uniform(), rng%uniform(), rng%uniform()] * box
            rr = random_rotation(rng)
            sc = 0.5_wp + rng%uniform()
            call fast%block_particle(body%shape, x, rr, sc, sc * body%r_min, sc * body%r_max, body=body)
            call slow%block_particle(body%shape, x, rr, sc, sc * body%r_min, sc * body%r_max)
         end do
         nb = count(slow%blocked)
         call check(error, nb > size(slow%blocked) / 20, "a good part of the grid is blocked")
         if (allocated(error)) return
         call check(error, count(fast%blocked .neqv. slow%blocked), 0, "cells blocked differently")
         if (allocated(error)) return
         call check(error, fast%stale, slow%stale, "stale counts")
         if (allocated(error)) return
      end do
   end subroutine test_void_bounds

   !> Room reserved after 3,000 particles (beyond the initial 4,096), the arrays grown past it, the
   !> record list too: every particle keeps its pose and the neighbour query still equals brute force.
   subroutine test_reserve(error)
      type(error_type), allocatable, intent(out) :: error
      type(packing_type) :: pk
      type(rng_type) :: rng
      integer, parameter :: n = 9000
      real(wp) :: x(3, n), r(3, 3, n), sc(n), q(3), rq
      integer, allocatable :: ids(:)
      real(wp), allocatable :: shifts(:, :)
      integer :: i, k, m, j, nbrute
      call sphere_packing(pk, .true., [40.0_wp, 40.0_wp, 40.0_wp], error)
      if (allocated(error)) return
      call new_rng(rng, 5_i8, 0_i8)
      do i = 1, n
         if (i == 3001) call pk%reserve(5000)
         x(:, i) = [rng%uniform(), rng%uniform(), rng%uniform()] * pk%p%box
         r(:, :, i) = random_rotation(rng)
         sc(i) = 0.1_wp * 10.0_wp**rng%uniform()
         call pk%add(1, x(:, i), r(:, :, i), sc(i), 1)
      end do
      call check(error, size(pk%scale) >= n .and. size(pk%owner) >= n, "capacity for every particle")
      if (allocated(error)) return
      call check(error, all(pk%center(:, :n) == x) .and. all(pk%rot(:, :, :n) == r) .and. all(pk%scale(:n) == sc), &
                 "poses kept through reserve and growth")
      if (allocated(error)) return
      do k = 1, 100
         q = [rng%uniform(), rng%uniform(), rng%uniform()] * pk%p%box
         rq = 0.1_wp * 10.0_wp**rng%uniform()
         call pk%neighbours(q, rq, ids, shifts, m)
         nbrute = 0
         do j = 1, pk%np
            if (distance(pk, pk%center(:, j), q) < rq + pk%rho(j)) nbrute = nbrute + 1
         end do
         call check(error, m, nbrute, "neighbours vs brute force after growth")
         if (allocated(error)) return
      end do
      call pk%release()
      call check(error, .not. allocated(pk%cl%blocks) .and. allocated(pk%center), "release frees the cell list only")
   end subroutine test_reserve
end module test_packing
