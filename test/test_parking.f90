!> Tests of the parking infrastructure: the hierarchical cell list against brute force for
!> sizes differing 1000:1, in periodic and non-periodic boxes, and the parking engine (the audit's
!> own tests: test_audit).
module test_parking
   use test_helpers, only: run_nml
   use anm_core_kinds, only: wp, i8
   use anm_core_error, only: error_type
   use anm_core_random, only: rng_type, new_rng
   use anm_neighbours_cell_list, only: cell_list_type, new_cell_list
   use anm_io_model, only: model_type
   use anm_audit_verify, only: verify_report_type, verify_model
   use anm_shapes_analytic, only: sphere_shape, ellipsoid_shape
   use anm_geometry_rotation, only: random_rotation
   use anm_io_model, only: write_model, read_model
   use omp_lib, only: omp_set_num_threads, omp_get_max_threads
   use anm_testing, only: unittest_type, new_unittest, check
   implicit none
   private
   public :: collect_parking

contains

   !> Tests of this suite.
   subroutine collect_parking(tests)
      type(unittest_type), allocatable, intent(out) :: tests(:)
      tests = [ &
              new_unittest("cell list equals brute force, periodic, sizes 1000:1", test_cells_periodic), &
              new_unittest("cell list equals brute force, walls", test_cells_walls), &
              new_unittest("cell list finds all images in a small periodic box", test_cells_images), &
              new_unittest("cell list: reorder keeps the candidates and their order", test_cells_reorder), &
              new_unittest("neighbours: candidates, certain overlaps, id range = brute force, periodic", &
                           test_neighbours_periodic), &
              new_unittest("neighbours: candidates, certain overlaps, id range = brute force, walls", test_neighbours_walls), &
              new_unittest("neighbours: all images in a small periodic box", test_neighbours_images), &
              new_unittest("RSA of spheres approaches saturation (>= 0.36)", test_rsa_spheres), &
              new_unittest("synthetic mortar reaches every target within 1 % and verifies", test_small_job), &
              new_unittest("walls: particles stay inside and verify passes", test_walls_job), &
              new_unittest("same seed gives the same model, another seed another", test_reproducible), &
              new_unittest("an unreachable target ends with a shortfall, not a loop", test_shortfall), &
              new_unittest("an unreadable shape folder names the variable", test_bad_source), &
              new_unittest("shell modes keep surface gaps >= 2t, >= t, >= 0 (spheres)", test_shell_modes), &
              new_unittest("1 and 2 threads give the same model", test_threads), &
              new_unittest("batches give the serial model (dense spheres, shapes with shells)", test_batches), &
              new_unittest("void-targeted placement: valid model, fewer wasted attempts", test_void), &
              new_unittest("void placement: max_batch=1 and 2 threads with large batches give the same model", &
                           test_void_batches), &
              new_unittest("max_failures: the thesis' model is a prefix, more particles follow", test_max_failures), &
              new_unittest("rounding of a sieve moves to the next: total within half a grain", test_carry), &
              new_unittest("the thesis' rules: overshoot ends each sieve at or above its own target", test_thesis_rules)]
   end subroutine collect_parking

   subroutine run_case(error, periodic, box, rmin, rmax, n, nq)
      type(error_type), allocatable, intent(out) :: error
      logical, intent(in) :: periodic
      real(wp), intent(in) :: box(3), rmin, rmax
      integer, intent(in) :: n, nq
      type(cell_list_type) :: cl
      type(rng_type) :: rng
      real(wp), allocatable :: c(:, :), rho(:), shift(:, :)
      integer, allocatable :: cand(:)
      real(wp) :: q(3), rq, d(3), lim
      integer :: i, k, ncand, nbrute, s1, s2, s3, hits
      call new_rng(rng, 11_i8, 0_i8)
      allocate (c(3, n), rho(n))
      call new_cell_list(cl, box, periodic, rmin)
      do i = 1, n
         c(:, i) = [rng%uniform(), rng%uniform(), rng%uniform()] * box
         ! log-uniform radii between rmin and rmax
         rho(i) = rmin * (rmax / rmin)**rng%uniform()
         call cl%insert(i, c(:, i), rho(i))
         ! blocks laid out in cell order half way: later insertions go on from there
         if (i == n / 2) call cl%reorder()
      end do
      do k = 1, nq
         q = [rng%uniform(), rng%uniform(), rng%uniform()] * box
         rq = rmin * (rmax / rmin)**rng%uniform()
         call cl%query(q, rq, c, rho, cand, shift, ncand)
         nbrute = 0
         do i = 1, n
            lim = rq + rho(i)
            d = c(:, i) - q
            do s3 = -1, 1
               do s2 = -1, 1
                  do s1 = -1, 1
                     if (.not. periodic .and. any([s1, s2, s3] /= 0)) cycle
                     if (sum((d + [s1, s2, s3] * box)**2) < lim * lim) nbrute = nbrute + 1
                  end do
               end do
            end do
         end do
         hits = 0
         do i = 1, ncand
            d = c(:, cand(i)) + shift(:, i) - q
            if (sum(d**2) < (rq + rho(cand(i)))**2) hits = hits + 1
         end do
         call check(error, ncand, nbrute, "candidates vs brute force")
         if (allocated(error)) return
         call check(error, hits, ncand, "every candidate really intersects")
         if (allocated(error)) return
      end do
   end subroutine run_case

   !> `reorder` (blocks in cell order) changes neither the candidates of `query` and `neighbours`
   !> nor their order: 3000 particles of radii 1:20 in a periodic box, 200 queries before and after.
   subroutine test_cells_reorder(error)
      type(error_type), allocatable, intent(out) :: error
      integer, parameter :: n = 3000, nq = 200
      type(cell_list_type) :: cl
      type(rng_type) :: rng
      real(wp) :: c(3, n), rho(n), q(3, nq), rq(nq), box(3)
      real(wp), allocatable :: shift(:, :)
      integer, allocatable :: cand(:), before(:, :), after(:, :)
      integer :: i, k, ncand, pass
      logical :: hit
      box = [10.0_wp, 12.0_wp, 9.0_wp]
      call new_rng(rng, 17_i8, 0_i8)
      call new_cell_list(cl, box, .true., 0.05_wp)
      do i = 1, n
         c(:, i) = [rng%uniform(), rng%uniform(), rng%uniform()] * box
         rho(i) = 0.05_wp * 20.0_wp**rng%uniform()
         call cl%insert(i, c(:, i), rho(i), rin=0.5_wp * rho(i))
      end do
      do k = 1, nq
         q(:, k) = [rng%uniform(), rng%uniform(), rng%uniform()] * box
         rq(k) = 0.05_wp * 20.0_wp**rng%uniform()
      end do
      allocate (before(0:2 * n, 2 * nq), after(0:2 * n, 2 * nq))
      do pass = 1, 2
         do k = 1, nq
            call cl%query(q(:, k), rq(k), c, rho, cand, shift, ncand)
            if (pass == 1) then
               before(0, k) = ncand
               before(1:ncand, k) = cand(:ncand)
            else
               after(0, k) = ncand
               after(1:ncand, k) = cand(:ncand)
            end if
            call cl%neighbours(q(:, k), rq(k), cand, shift, ncand, hit)
            if (pass == 1) then
               before(0, nq + k) = ncand
               before(1:ncand, nq + k) = cand(:ncand)
            else
               after(0, nq + k) = ncand
               after(1:ncand, nq + k) = cand(:ncand)
            end if
         end do
         if (pass == 1) call cl%reorder()
      end do
      do k = 1, 2 * nq
         call check(error, all(before(0:before(0, k), k) == after(0:before(0, k), k)), &
                    "candidates or their order changed by reorder")
         if (allocated(error)) return
      end do
      call check(error, sum(before(0, :)) > nq, "too few candidates to compare")
   end subroutine test_cells_reorder

   !> `neighbours` against brute force: with rin absent, the candidates (jmin < id <= jmax) are the
   !> particles (and images) whose bounding spheres meet the query's; with rin, `hit` is true
   !> exactly when one of them lies closer than rin + rin_j, and otherwise the candidates are
   !> complete. Radii log-uniform over rmin..rmax, inscribed radii a random 30-100 % of them.
   subroutine neighbours_case(error, periodic, box, rmin, rmax, n, nq)
      type(error_type), allocatable, intent(out) :: error
      logical, intent(in) :: periodic
      real(wp), intent(in) :: box(3), rmin, rmax
      integer, intent(in) :: n, nq
      type(cell_list_type) :: cl
      type(rng_type) :: rng
      real(wp), allocatable :: c(:, :), rho(:), rin(:), shift(:, :)
      integer, allocatable :: cand(:)
      real(wp) :: q(3), rq, qin, d(3), lim, lin, r2
      integer :: i, k, ncand, nbrute, s1, s2, s3, hits, jmin, jmax, nin
      logical :: hit
      call new_rng(rng, 13_i8, 0_i8)
      allocate (c(3, n), rho(n), rin(n))
      call new_cell_list(cl, box, periodic, rmin)
      do i = 1, n
         c(:, i) = [rng%uniform(), rng%uniform(), rng%uniform()] * box
         rho(i) = rmin * (rmax / rmin)**rng%uniform()
         rin(i) = rho(i) * (0.3_wp + 0.7_wp * rng%uniform())
         call cl%insert(i, c(:, i), rho(i), rin=rin(i))
         if (i == n / 2) call cl%reorder()
      end do
      do k = 1, nq
         q = [rng%uniform(), rng%uniform(), rng%uniform()] * box
         rq = rmin * (rmax / rmin)**rng%uniform()
         qin = rq * (0.3_wp + 0.7_wp * rng%uniform())
         jmin = merge(0, int(n * rng%uniform()), mod(k, 2) == 0)
         jmax = merge(n, jmin + int((n - jmin) * rng%uniform()), mod(k, 3) /= 0)
         nbrute = 0
         nin = 0
         do i = jmin + 1, jmax
            lim = rq + rho(i)
            lin = qin + rin(i)
            d = c(:, i) - q
            do s3 = -1, 1
               do s2 = -1, 1
                  do s1 = -1, 1
                     if (.not. periodic .and. any([s1, s2, s3] /= 0)) cycle
                     r2 = sum((d + [s1, s2, s3] * box)**2)
                     if (r2 < lim * lim) nbrute = nbrute + 1
                     if (r2 < lin * lin) nin = nin + 1
                  end do
               end do
            end do
         end do
         call cl%neighbours(q, rq, cand, shift, ncand, hit, jmin=jmin, jmax=jmax)
         call check(error, ncand, nbrute, "candidates vs brute force")
         if (allocated(error)) return
         call check(error, .not. hit, "hit without rin")
         if (allocated(error)) return
         hits = 0
         do i = 1, ncand
            d = c(:, cand(i)) + shift(:, i) - q
            if (sum(d**2) < (rq + rho(cand(i)))**2 .and. cand(i) > jmin .and. cand(i) <= jmax) hits = hits + 1
         end do
         call check(error, hits, ncand, "every candidate intersects, jmin < id <= jmax")
         if (allocated(error)) return
         call cl%neighbours(q, rq, cand, shift, ncand, hit, rin=qin, jmin=jmin, jmax=jmax)
         call check(error, hit .eqv. nin > 0, "certain overlap found iff brute force has one")
         if (allocated(error)) return
         if (.not. hit) call check(error, ncand, nbrute, "candidates when no certain overlap")
         if (allocated(error)) return
      end do
   end subroutine neighbours_case

   subroutine test_neighbours_periodic(error)
      type(error_type), allocatable, intent(out) :: error
      call neighbours_case(error, .true., [20.0_wp, 20.0_wp, 20.0_wp], 0.005_wp, 5.0_wp, 3000, 800)
   end subroutine test_neighbours_periodic

   subroutine test_neighbours_walls(error)
      type(error_type), allocatable, intent(out) :: error
      call neighbours_case(error, .false., [20.0_wp, 15.0_wp, 10.0_wp], 0.01_wp, 2.0_wp, 3000, 2000)
   end subroutine test_neighbours_walls

   subroutine test_neighbours_images(error)
      type(error_type), allocatable, intent(out) :: error
      call neighbours_case(error, .true., [4.0_wp, 4.0_wp, 4.0_wp], 0.5_wp, 1.5_wp, 50, 500)
   end subroutine test_neighbours_images

   subroutine test_cells_periodic(error)
      type(error_type), allocatable, intent(out) :: error
      call run_case(error, .true., [20.0_wp, 20.0_wp, 20.0_wp], 0.005_wp, 5.0_wp, 3000, 800)
   end subroutine test_cells_periodic

   subroutine test_cells_walls(error)
      type(error_type), allocatable, intent(out) :: error
      call run_case(error, .false., [20.0_wp, 15.0_wp, 10.0_wp], 0.01_wp, 2.0_wp, 3000, 2000)
   end subroutine test_cells_walls

   subroutine test_cells_images(error)
      type(error_type), allocatable, intent(out) :: error
      call run_case(error, .true., [4.0_wp, 4.0_wp, 4.0_wp], 0.5_wp, 1.5_wp, 50, 500)
   end subroutine test_cells_images
   !> Batches of speculated particles (2 threads, phase 2 re-checks and continuations) against
   !> the plain serial algorithm (one particle at a time): dense spheres in a small box, where
   !> particles of a batch often meet, and a shaped mixture with shells.
   subroutine test_batches(error)
      type(error_type), allocatable, intent(out) :: error
      type(model_type) :: a, b
      integer :: nthreads, k
      character(len=*), parameter :: text(2) = [character(len=400) :: &
         "&box length = 9, 9, 9 /"//new_line("a")//"&sieves nsieve = 1, min_width = 2, max_width = 2, " &
         //"fraction = 0.34, source = 'sphere', order = 0 /"//new_line("a")//"&parking max_locations = 20000 /", &
         "&box length = 7, 7, 7 /"//new_line("a")// &
         "&sieves nsieve = 2, min_width = 1.5, 0.4, max_width = 1.8, 0.5, fraction = 0.1, 0.08, order = 8, 4 /" &
         //new_line("a")//"&synthetic count = 4 /"//new_line("a")// &
         "&shells nlayer = 1, thickness = 0.03, mode = 'exclude' /"//new_line("a")//"&run seed = 6 /"]
      nthreads = omp_get_max_threads()
      do k = 1, 2
         call omp_set_num_threads(1)
         call run_nml("serial.nml", trim(text(k)), a, error, max_batch=1)
         call omp_set_num_threads(2)
         if (.not. allocated(error)) call run_nml("batched.nml", trim(text(k)), b, error)
         call omp_set_num_threads(nthreads)
         if (allocated(error)) return
         print '(a,i0,a,i0,a,i0,a)', "        case ", k, ": ", a%np, " particles, ", a%attempts, " attempts"
         call check(error, a%np == b%np .and. a%attempts == b%attempts, "particle or attempt counts differ")
         if (allocated(error)) return
         call check(error, all(a%center == b%center) .and. all(a%rotation == b%rotation) .and. &
                    all(a%scale == b%scale) .and. all(a%shape == b%shape), "batched model differs from the serial one")
         if (allocated(error)) return
      end do
   end subroutine test_batches

   subroutine test_rsa_spheres(error)
      type(error_type), allocatable, intent(out) :: error
      type(model_type) :: m
      type(verify_report_type) :: rep
      ! random sequential addition saturates at 0.3841 (Torquato et al. 2006); a large budget
      ! per particle brings a small periodic box close to it
      call run_nml("rsa.nml", "&box length = 12, 12, 12, periodic = .true. /"//new_line("a")// &
                   "&sieves nsieve = 1, min_width = 2, max_width = 2, fraction = 0.384, source = 'sphere', order = 0 /" &
                   //new_line("a")//"&parking max_locations = 200000 /", m, error)
      if (allocated(error)) return
      print '(a,f7.4,a,i0,a)', "        RSA spheres: packing fraction ", m%achieved_fraction(1), " (", m%count(1), &
         " spheres)"
      call check(error, m%achieved_fraction(1) >= 0.36_wp, "RSA density below 0.36")
      if (allocated(error)) return
      call verify_model(m, 40, rep)
      call check(error, rep%overlapping_pairs == 0_i8, "verify found overlapping spheres")
   end subroutine test_rsa_spheres

   subroutine test_small_job(error)
      type(error_type), allocatable, intent(out) :: error
      type(model_type) :: m
      type(verify_report_type) :: rep
      integer :: s
      call run_nml("small.nml", "&box length = 8, 8, 8 /"//new_line("a")// &
                   "&sieves nsieve = 3, min_width = 2.0, 1.0, 0.5, max_width = 2.4, 1.2, 0.6, fraction = 0.12, 0.08, 0.05, " &
                   //"order = 10, 6, 4 /"//new_line("a")//"&synthetic count = 6 /"//new_line("a")//"&run seed = 3 /", m, error)
      if (allocated(error)) return
      do s = 1, 3
         print '(a,i0,a,f7.4,a,f7.4,a,i0)', "        sieve ", s, ": ", m%achieved_fraction(s), " of ", &
            m%target_fraction(s), ", particles ", m%count(s)
         call check(error, m%achieved_fraction(s), m%target_fraction(s), "sieve target", thr=0.01_wp)
         if (allocated(error)) return
      end do
      call verify_model(m, 60, rep)
      print '(a,i0,a,i0,a,es9.2)', "        verify: ", rep%pairs_checked, " pairs, ", rep%overlapping_pairs, &
         " overlapping, deepest ", rep%max_depth
      call check(error, rep%overlapping_pairs == 0_i8, "verify found overlaps")
   end subroutine test_small_job

   subroutine test_walls_job(error)
      type(error_type), allocatable, intent(out) :: error
      type(model_type) :: m
      type(verify_report_type) :: rep
      call run_nml("walls.nml", "&box length = 8, 8, 8, periodic = .false. /"//new_line("a")// &
                   "&sieves nsieve = 2, min_width = 2.0, 1.0, max_width = 2.4, 1.2, fraction = 0.15, 0.08, order = 8, 6 /" &
                   //new_line("a")//"&synthetic count = 6 /"//new_line("a")//"&parking max_locations = 20000 /", m, error)
      if (allocated(error)) return
      call verify_model(m, 60, rep)
      call check(error, rep%wall_violations == 0 .and. rep%overlapping_pairs == 0_i8, "walls or overlaps violated")
      if (allocated(error)) return
      call check(error, m%achieved_fraction(1), 0.15_wp, "first sieve", thr=0.01_wp)
   end subroutine test_walls_job

   subroutine test_reproducible(error)
      type(error_type), allocatable, intent(out) :: error
      type(model_type) :: a, b, c
      character(len=*), parameter :: base = "&box length = 6, 6, 6 /"//new_line("a")// &
         "&sieves nsieve = 2, min_width = 1.5, 0.6, max_width = 2.0, 0.8, fraction = 0.1, 0.05, order = 8, 4 /" &
         //new_line("a")//"&synthetic count = 4 /"//new_line("a")
      call run_nml("repro1.nml", base//"&run seed = 9 /", a, error)
      if (allocated(error)) return
      call run_nml("repro2.nml", base//"&run seed = 9 /", b, error)
      if (allocated(error)) return
      call run_nml("repro3.nml", base//"&run seed = 10 /", c, error)
      if (allocated(error)) return
      call check(error, a%np == b%np .and. all(a%center == b%center) .and. all(a%rotation == b%rotation) &
                 .and. all(a%scale == b%scale) .and. all(a%shape == b%shape), "same seed, different model")
      if (allocated(error)) return
      call check(error, a%np /= c%np .or. any(a%center(:, :min(a%np, c%np)) /= c%center(:, :min(a%np, c%np))), &
                 "different seed, same model")
   end subroutine test_reproducible

   subroutine test_shortfall(error)
      type(error_type), allocatable, intent(out) :: error
      type(model_type) :: m
      ! spheres cannot reach 0.6 by random sequential addition
      call run_nml("short.nml", "&box length = 8, 8, 8 /"//new_line("a")// &
                   "&sieves nsieve = 1, min_width = 2, max_width = 2, fraction = 0.6, source = 'sphere', order = 0 /" &
                   //new_line("a")//"&parking max_locations = 200 /", m, error)
      if (allocated(error)) return
      call check(error, m%achieved_fraction(1) < 0.45_wp .and. m%count(1) > 10, "shortfall not reported")
   end subroutine test_shortfall

   subroutine test_bad_source(error)
      type(error_type), allocatable, intent(out) :: error
      type(model_type) :: m
      type(error_type), allocatable :: err
      call run_nml("badsrc.nml", "&box length = 8, 8, 8 /"//new_line("a")// &
                   "&sieves nsieve = 1, min_width = 2, max_width = 2.2, fraction = 0.1, source = 'no/such/folder' /", m, err)
      call check(error, allocated(err), "missing shape folder accepted")
      if (allocated(error)) return
      print '(a)', "        refused as expected: "//err%message
      call check(error, index(err%message, "source") > 0 .and. index(err%message, "no/such/folder") > 0, &
                 "message must name the variable and the folder: "//err%message)
   end subroutine test_bad_source
   subroutine test_shell_modes(error)
      type(error_type), allocatable, intent(out) :: error
      character(len=*), parameter :: modes(3) = [character(len=13) :: "exclude", "shell_overlap", "overlap"]
      real(wp), parameter :: factor(3) = [2.0_wp, 1.0_wp, 0.0_wp]
      type(model_type) :: m
      real(wp) :: gap, gmin, d(3), t
      integer :: k, i, j
      ! spheres of radius 1 (length 2) with a shell of 5 % of the length: t = 0.1 mm; for spheres
      ! the surface gap is |c_i - c_j| - 2 exactly (nearest periodic image)
      t = 0.1_wp
      do k = 1, 3
         call run_nml("modes.nml", "&box length = 8, 8, 8 /"//new_line("a")// &
                      "&sieves nsieve = 1, min_width = 2, max_width = 2, fraction = 0.3, source = 'sphere', order = 0 /" &
                      //new_line("a")//"&parking max_locations = 20000 /"//new_line("a")// &
                      "&shells nlayer = 1, thickness = 0.05, mode = '"//trim(modes(k))//"' /", m, error)
         if (allocated(error)) return
         gmin = huge(1.0_wp)
         do i = 1, m%np
            do j = i + 1, m%np
               d = m%center(:, i) - m%center(:, j)
               d = d - m%box * anint(d / m%box)
               gmin = min(gmin, norm2(d) - 2.0_wp)
            end do
         end do
         print '(a,a13,a,f8.5,a,f6.3,a,f7.4)', "        mode ", modes(k), ": smallest gap ", gmin, &
            " mm (bound ", factor(k) * t, "), fraction ", m%achieved_fraction(1)
         call check(error, gmin >= factor(k) * t - 1.0e-9_wp, "gap below the mode's bound")
         if (allocated(error)) return
         if (k < 3) then
            ! the bound is attained closely: random parking brings some pairs near contact
            call check(error, gmin < factor(k) * t + 0.2_wp, "gap far above the bound: shells not used?")
            if (allocated(error)) return
         end if
      end do
   end subroutine test_shell_modes
   subroutine test_threads(error)
      type(error_type), allocatable, intent(out) :: error
      type(model_type) :: a, b
      integer :: nthreads
      character(len=*), parameter :: text = "&box length = 8, 8, 8 /"//new_line("a")// &
         "&sieves nsieve = 3, min_width = 2.0, 1.0, 0.5, max_width = 2.4, 1.2, 0.6, fraction = 0.12, 0.08, 0.05, " &
         //"order = 10, 6, 4 /"//new_line("a")//"&synthetic count = 6 /"//new_line("a")// &
         "&shells nlayer = 1, thickness = 0.02, mode = 'shell_overlap' /"//new_line("a")//"&run seed = 4 /"
      nthreads = omp_get_max_threads()
      call omp_set_num_threads(1)
      call run_nml("threads1.nml", text, a, error)
      call omp_set_num_threads(2)
      if (.not. allocated(error)) call run_nml("threads2.nml", text, b, error)
      call omp_set_num_threads(nthreads)
      if (allocated(error)) return
      print '(a,i0,a,i0,a)', "        1 thread: ", a%np, " particles, 2 threads: ", b%np, " particles"
      call check(error, a%np == b%np .and. a%attempts == b%attempts, "particle or attempt counts differ")
      if (allocated(error)) return
      call check(error, all(a%center == b%center) .and. all(a%rotation == b%rotation) .and. all(a%scale == b%scale) &
                 .and. all(a%shape == b%shape) .and. all(a%sieve == b%sieve), "models differ between 1 and 2 threads")
   end subroutine test_threads
   subroutine test_void(error)
      type(error_type), allocatable, intent(out) :: error
      type(model_type) :: u, v
      type(verify_report_type) :: rep
      character(len=*), parameter :: base = "&box length = 10, 10, 10 /"//new_line("a")// &
         "&sieves nsieve = 1, min_width = 2, max_width = 2, fraction = 0.384, source = 'sphere', order = 0 /" &
         //new_line("a")
      call run_nml("uniform.nml", base//"&parking max_locations = 2000 /", u, error)
      if (allocated(error)) return
      call run_nml("void.nml", base//"&parking max_locations = 2000, placement = 'void' /", v, error)
      if (allocated(error)) return
      print '(a,f7.4,a,i0,a,f7.4,a,i0,a)', "        spheres, 2000 locations: uniform ", u%achieved_fraction(1), " (", &
         u%attempts, " attempts), void ", v%achieved_fraction(1), " (", v%attempts, " attempts)"
      call verify_model(v, 40, rep)
      call check(error, rep%overlapping_pairs == 0_i8, "void placement produced overlaps")
      if (allocated(error)) return
      call check(error, v%achieved_fraction(1) >= u%achieved_fraction(1), "void placement packed less")
   end subroutine test_void

   !> Void placement does not depend on batching: the serial algorithm (one thread, max_batch=1)
   !> and two threads with batches as large as they grow give the same model (two sieves, so
   !> that the second starts from a grid blocked by the first; walls and periodic).
   subroutine test_void_batches(error)
      type(error_type), allocatable, intent(out) :: error
      type(model_type) :: a, b
      integer :: nthreads, i
      character(len=*), parameter :: sieves = "&sieves nsieve = 2, min_width = 2, 1, max_width = 2.4, 1.2, "// &
         "fraction = 0.3, 0.1, source = 'sphere', 'sphere', order = 0, 0 /"//new_line("a")// &
         "&parking max_locations = 300, placement = 'void' /"
      character(len=60), parameter :: boxes(2) = [character(len=60) :: "&box length = 9, 9, 9 /", &
                                                   "&box length = 9, 9, 9, periodic = .false. /"]
      nthreads = omp_get_max_threads()
      do i = 1, 2
         call omp_set_num_threads(1)
         call run_nml("void_serial.nml", trim(boxes(i))//new_line("a")//sieves, a, error, max_batch=1)
         call omp_set_num_threads(2)
         if (.not. allocated(error)) call run_nml("void_batched.nml", trim(boxes(i))//new_line("a")//sieves, b, error)
         call omp_set_num_threads(nthreads)
         if (allocated(error)) return
         print '(a,i0,a,i0,a,2i6)', "        case ", i, ": ", a%np, " particles, per sieve", a%count
         call check(error, a%np == b%np .and. a%attempts == b%attempts, "particle or attempt counts differ")
         if (allocated(error)) return
         call check(error, all(a%center == b%center) .and. all(a%rotation == b%rotation) .and. &
                    all(a%scale == b%scale), "the batched void model differs from the serial one")
         if (allocated(error)) return
      end do
   end subroutine test_void_batches

   subroutine test_max_failures(error)
      type(error_type), allocatable, intent(out) :: error
      type(model_type) :: a, b
      integer :: n
      character(len=*), parameter :: base = "&box length = 8, 8, 8 /"//new_line("a")// &
         "&sieves nsieve = 1, min_width = 2, max_width = 2, fraction = 0.6, source = 'sphere', order = 0 /" &
         //new_line("a")
      ! the particles are the same sequence of attempt streams: a failed particle is skipped, so the
      ! model that stops at the first failure is the beginning of the one that allows 30
      call run_nml("fail1.nml", base//"&parking max_locations = 50 /", a, error)
      if (allocated(error)) return
      call run_nml("fail30.nml", base//"&parking max_locations = 50, max_failures = 30 /", b, error)
      if (allocated(error)) return
      n = a%np
      print '(a,i0,a,i0,a)', "        spheres, 50 locations: ", a%np, " particles (max_failures = 1), ", b%np, &
         " (30)"
      call check(error, b%np > a%np, "max_failures = 30 parked no more particles than 1")
      if (allocated(error)) return
      call check(error, all(a%center == b%center(:, :n)) .and. all(a%rotation == b%rotation(:, :, :n)), &
                 "the model with max_failures = 1 is not the beginning of the other")
      if (allocated(error)) return
      call check(error, b%achieved_fraction(1) < 0.6_wp, "an unreachable target was reached")
   end subroutine test_max_failures

   subroutine test_carry(error)
      type(error_type), allocatable, intent(out) :: error
      type(model_type) :: m
      real(wp) :: v1, v2, total
      ! spheres of diameter 4 and 2 in a 20 mm box: one coarse grain is 0.0042 of the box, so
      ! 0.052 ends at 12 grains (0.0503); the next sieve takes the 0.0017 left over, and the total
      ! lands within half a fine grain (0.00026) of 0.102. Without the carry it would miss by 0.0017.
      call run_nml("carry.nml", "&box length = 20, 20, 20 /"//new_line("a")// &
                   "&sieves nsieve = 2, min_width = 4, 2, max_width = 4, 2, fraction = 0.052, 0.05, source = 2*'sphere', " &
                   //"order = 2*0 /"//new_line("a")//"&parking max_locations = 20000 /", m, error)
      if (allocated(error)) return
      v1 = 4.0_wp / 3.0_wp * acos(-1.0_wp) * 2.0_wp**3 / 8000.0_wp
      v2 = v1 / 8.0_wp
      total = sum(m%achieved_fraction)
      print '(a,2(i0,a),f8.5,a,f8.5)', "        ", m%count(1), " + ", m%count(2), " spheres, total ", total, &
         " of ", sum(m%target_fraction)
      call check(error, m%count(1) == 12, "coarse sieve should end at 12 grains")
      if (allocated(error)) return
      call check(error, abs(total - 0.102_wp) <= 0.5_wp * v2 + 1.0e-12_wp, "total not within half a fine grain")
      if (allocated(error)) return
      call check(error, abs(m%achieved_fraction(2) - (0.102_wp - 12 * v1)) <= 0.5_wp * v2 + 1.0e-12_wp, &
                 "fine sieve did not take the coarse sieve's remainder")
   end subroutine test_carry
   !> The thesis' sieve-volume rules (docs/thesis-gaps.md) on the setup of test_carry, where the
   !> counts follow from the target alone: coarse spheres of 0.0041888 of the box, target 0.052 =
   !> 12.41 grains; fine 0.00052360, target 0.05 = 95.49 grains.
   subroutine test_thesis_rules(error)
      type(error_type), allocatable, intent(out) :: error
      type(model_type) :: m
      real(wp) :: v1, v2
      character(len=*), parameter :: base = "&box length = 20, 20, 20 /"//new_line("a")// &
         "&sieves nsieve = 2, min_width = 4, 2, max_width = 4, 2, fraction = 0.052, 0.05, source = 2*'sphere', " &
         //"order = 2*0 /"//new_line("a")//"&parking max_locations = 20000"
      v1 = 4.0_wp / 3.0_wp * acos(-1.0_wp) * 2.0_wp**3 / 8000.0_wp
      v2 = v1 / 8.0_wp
      ! overshoot, no carry (the thesis): each sieve ends at the first grain that reaches its own
      ! target: ceiling(12.41) = 13 and ceiling(95.49) = 96
      call run_nml("thesis-rules.nml", base//", last_particle = 'overshoot', sieve_carry = 'none' /", m, error)
      if (allocated(error)) return
      print '(a,2(i0,a),2f9.5)', "        overshoot, no carry: ", m%count(1), " + ", m%count(2), " spheres, ", &
         m%achieved_fraction
      call check(error, all(m%achieved_fraction >= m%target_fraction), "a sieve ended below its own target")
      if (allocated(error)) return
      call check(error, all(m%achieved_fraction - m%target_fraction < [v1, v2]), "a sieve went a whole grain past its target")
      if (allocated(error)) return
      call check(error, m%count(1) == 13 .and. m%count(2) == 96, "expected 13 + 96 grains")
      if (allocated(error)) return
      ! overshoot with the rounding carry: the coarse excess (13 v1 - 0.052) comes off the fine target
      call run_nml("overshoot-carry.nml", base//", last_particle = 'overshoot' /", m, error)
      if (allocated(error)) return
      print '(a,2(i0,a),2f9.5)', "        overshoot, carry: ", m%count(1), " + ", m%count(2), " spheres, ", &
         m%achieved_fraction
      call check(error, m%count(1) == 13 .and. m%count(2) == ceiling((0.102_wp - 13 * v1) / v2), &
                 "the fine sieve did not aim at 0.102 minus the coarse volume")
      if (allocated(error)) return
      call check(error, sum(m%achieved_fraction) >= 0.102_wp .and. sum(m%achieved_fraction) < 0.102_wp + v2, &
                 "total not within one fine grain above 0.102")
      if (allocated(error)) return
      ! the closer rule without the carry: 12 coarse grains, the fine sieve within half a grain of 0.05
      call run_nml("closer-nocarry.nml", base//", sieve_carry = 'none' /", m, error)
      if (allocated(error)) return
      call check(error, m%count(1) == 12 .and. abs(m%achieved_fraction(2) - 0.05_wp) <= 0.5_wp * v2 + 1.0e-12_wp, &
                 "without the carry the fine sieve must aim at its own 0.05")
   end subroutine test_thesis_rules
end module test_parking
