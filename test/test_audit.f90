!> Tests of the audit (`anm verify`, anm_audit_verify): spheres whose overlaps are known exactly
!> (clear, overlapping, across the periodic boundary, through a wall), and the pruned sampling
!> against testing every sample on a parked model.
module test_audit
   use test_helpers, only: run_nml
   use anm_core_kinds, only: wp, i8
   use anm_core_error, only: error_type
   use anm_core_random, only: rng_type, new_rng
   use anm_io_model, only: model_type
   use anm_audit_verify, only: verify_report_type, verify_model, verify_split_type
   use anm_shapes_analytic, only: sphere_shape, ellipsoid_shape
   use anm_sh_expansion, only: sh_expansion_type, new_sh_expansion_real
   use anm_audit_bounds, only: radius_bounds_type, new_radius_bounds, curvature_bound, bound_at, ball_beyond
   use anm_geometry_rotation, only: random_rotation
   use anm_testing, only: unittest_type, new_unittest, check
   implicit none
   private
   public :: collect_audit

   !> One process of a distributed audit, without MPI: `reduce` leaves the slab's own report.
   type, extends(verify_split_type) :: slab_only_type
   contains
      procedure :: reduce => keep_report
   end type slab_only_type

contains

   !> Tests of this suite.
   subroutine collect_audit(tests)
      type(unittest_type), allocatable, intent(out) :: tests(:)
      tests = [ &
              new_unittest("verify: separated spheres pass", test_verify_clear), &
              new_unittest("verify: overlapping spheres fail with the exact depth", test_verify_overlap), &
              new_unittest("verify: overlap across the periodic boundary", test_verify_periodic), &
              new_unittest("verify: a particle through a wall fails", test_verify_wall), &
              new_unittest("verify: pruned sampling gives the report of every sample (sizes 8:1)", &
                           test_verify_pruning), &
              new_unittest("verify: a small overlap planted in a big parked model is found", test_verify_planted), &
              new_unittest("verify: the curvature bound of r holds and is exact for a zonal harmonic", &
                           test_curvature_bound), &
              new_unittest("verify: the cube-map bounds lie above r; a ball beyond them has no point inside", &
                           test_radius_bounds), &
              new_unittest("verify: ellipsoid and sphere at known gaps and overlaps (3:1 and 30:1 sizes)", &
                           test_verify_ellipsoids), &
              new_unittest("verify: the slabs of 2 and 3 processes share the pairs and walls exactly", &
                           test_verify_slabs)]
   end subroutine collect_audit

   !> A model of spheres of radius 1 (shape 1) at the given centres.
   function sphere_model(centers, periodic, box) result(m)
      real(wp), intent(in) :: centers(:, :)
      logical, intent(in) :: periodic
      real(wp), intent(in) :: box(3)
      type(model_type) :: m
      type(rng_type) :: rng
      integer :: p
      call new_rng(rng, 5_i8, 0_i8)
      m%box = box
      m%periodic = periodic
      allocate (m%shapes(1), m%shape_names(1))
      m%shapes(1) = sphere_shape(1.0_wp)
      m%shape_names(1) = "sphere"
      m%np = size(centers, 2)
      m%center = centers
      allocate (m%rotation(3, 3, m%np))
      do p = 1, m%np
         m%rotation(:, :, p) = random_rotation(rng)
      end do
      m%scale = [(1.0_wp, p=1, m%np)]
      m%shape = [(1, p=1, m%np)]
      m%nmax = [(0, p=1, m%np)]
      m%sieve = [(1, p=1, m%np)]
      m%min_width = [2.0_wp]
   end function sphere_model

   subroutine test_verify_clear(error)
      type(error_type), allocatable, intent(out) :: error
      type(verify_report_type) :: rep
      ! gap of 1e-3 between the first two, the third far away
      call verify_model(sphere_model(reshape([3.0_wp, 5.0_wp, 5.0_wp, 5.001_wp, 5.0_wp, 5.0_wp, 8.0_wp, 8.0_wp, 8.0_wp], &
                                             [3, 3]), .false., [10.0_wp, 10.0_wp, 10.0_wp]), 60, rep)
      call check(error, rep%pairs_checked >= 1_i8 .and. rep%overlapping_pairs == 0_i8 .and. rep%wall_violations == 0, &
                 "clear spheres flagged")
   end subroutine test_verify_clear

   subroutine test_verify_overlap(error)
      type(error_type), allocatable, intent(out) :: error
      type(verify_report_type) :: rep
      ! centres 1.98 apart: radial penetration 0.02 exactly along the line of centres
      call verify_model(sphere_model(reshape([3.0_wp, 5.0_wp, 5.0_wp, 4.98_wp, 5.0_wp, 5.0_wp], [3, 2]), .false., &
                                     [10.0_wp, 10.0_wp, 10.0_wp]), 120, rep)
      call check(error, rep%overlapping_pairs == 1_i8, "overlap not found")
      if (allocated(error)) return
      print '(a,es10.3,a)', "        sphere overlap depth found ", rep%max_depth, " (exact 2.0e-2)"
      call check(error, rep%max_depth, 0.02_wp, "depth", thr=2.0e-3_wp)
   end subroutine test_verify_overlap

   subroutine test_verify_periodic(error)
      type(error_type), allocatable, intent(out) :: error
      type(verify_report_type) :: rep
      ! 0.5 and 9.4 along x in a periodic 10 mm box: 1.1 apart through the boundary
      call verify_model(sphere_model(reshape([0.5_wp, 5.0_wp, 5.0_wp, 9.4_wp, 5.0_wp, 5.0_wp], [3, 2]), .true., &
                                     [10.0_wp, 10.0_wp, 10.0_wp]), 60, rep)
      call check(error, rep%overlapping_pairs == 1_i8, "periodic overlap not found")
   end subroutine test_verify_periodic

   subroutine test_verify_wall(error)
      type(error_type), allocatable, intent(out) :: error
      type(verify_report_type) :: rep
      call verify_model(sphere_model(reshape([0.99_wp, 5.0_wp, 5.0_wp], [3, 1]), .false., &
                                     [10.0_wp, 10.0_wp, 10.0_wp]), 60, rep)
      call check(error, rep%wall_violations, 1, "wall crossing not found")
   end subroutine test_verify_wall
   !> A parked model of synthetic shapes of two sizes (8:1), then the same with every particle
   !> grown by 0.2 % and by 3 % (shallow and deeper overlaps): neither the block bounds nor the
   !> certified first filter may change the pairs, the count of overlaps, the worst pair or the
   !> deepest penetration (against every sample of every pair).
   subroutine test_verify_pruning(error)
      type(error_type), allocatable, intent(out) :: error
      type(model_type) :: m
      type(verify_report_type) :: fast, full, indep
      real(wp), allocatable :: scale0(:)
      integer :: k
      real(wp), parameter :: grow(3) = [1.0_wp, 1.002_wp, 1.03_wp]
      call run_nml("prune.nml", "&box length = 6, 6, 6 /"//new_line("a")// &
                   "&sieves nsieve = 2, min_width = 2.0, 0.25, max_width = 2.4, 0.3, fraction = 0.15, 0.08, " &
                   //"order = 10, 5 /"//new_line("a")//"&synthetic count = 4 /"//new_line("a")//"&run seed = 5 /", m, error)
      if (allocated(error)) return
      scale0 = m%scale
      do k = 1, 3
         m%scale = scale0 * grow(k)
         call verify_model(m, 48, fast, filter=.true.)
         call verify_model(m, 48, full, prune=.false., filter=.false.)
         call verify_model(m, 48, indep, filter=.false.)
         print '(a,f6.3,a,i0,a,i0,a,es10.3)', "        scale x", grow(k), ": ", full%pairs_checked, " pairs, ", &
            full%overlapping_pairs, " overlapping, deepest ", full%max_depth
         call check(error, fast%pairs_checked == full%pairs_checked .and. &
                    fast%overlapping_pairs == full%overlapping_pairs .and. all(fast%worst == full%worst), &
                    "pruned report differs")
         if (allocated(error)) return
         call check(error, fast%max_depth, full%max_depth, "deepest penetration", thr=0.0_wp)
         if (allocated(error)) return
         ! the pruned audit without the certified filter (every pair sampled)
         call check(error, indep%pairs_checked == full%pairs_checked .and. indep%pairs_cleared == 0_i8 .and. &
                    indep%overlapping_pairs == full%overlapping_pairs .and. all(indep%worst == full%worst) .and. &
                    indep%max_depth == full%max_depth, "pruned independent report differs")
         if (allocated(error)) return
         call check(error, full%pairs_checked > 0_i8 .and. (k == 1 .or. full%overlapping_pairs > 0_i8), &
                    "no pairs or overlaps to compare")
         if (allocated(error)) return
      end do
   end subroutine test_verify_pruning

   !> A parked model of about 1,900 synthetic sand grains (order 5) passes; then one grain is moved
   !> towards its nearest neighbour until the dense sampling of that pair alone (no filter)
   !> finds a penetration of about 0.2 % of the grain size: the audit of the whole model (certified
   !> filter on) must report that pair as the deepest, with the same depth.
   subroutine test_verify_planted(error)
      type(error_type), allocatable, intent(out) :: error
      type(model_type) :: m, pair
      type(verify_report_type) :: rep
      real(wp) :: d(3), dq, u(3), lo, hi, t, best, target
      integer :: p, q, j, it
      call run_nml("planted.nml", "&box length = 6, 6, 6 /"//new_line("a")// &
                   "&sieves nsieve = 1, min_width = 0.25, max_width = 0.3, fraction = 0.12, order = 5 /" &
                   //new_line("a")//"&synthetic count = 6 /"//new_line("a")//"&run seed = 3 /", m, error)
      if (allocated(error)) return
      call verify_model(m, 48, rep)
      print '(a,i0,a,i0,a,i0,a)', "        ", m%np, " grains, ", rep%pairs_checked, " pairs, ", rep%pairs_cleared, &
         " cleared by the certified test"
      call check(error, m%np > 1000 .and. rep%overlapping_pairs == 0_i8 .and. rep%pairs_cleared > 0_i8, &
                 "parked model not clean or too small")
      if (allocated(error)) return
      ! nearest neighbour of grain p (minimum image)
      p = m%np / 2
      q = 0
      best = huge(1.0_wp)
      do j = 1, m%np
         if (j == p) cycle
         d = m%center(:, j) - m%center(:, p)
         d = d - m%box * anint(d / m%box)
         if (norm2(d) < best) then
            best = norm2(d)
            q = j
         end if
      end do
      d = m%center(:, q) - m%center(:, p)
      d = d - m%box * anint(d / m%box)
      dq = norm2(d)
      u = d / dq
      ! the pair on its own, q at p + d
      pair = m
      pair%np = 2
      pair%center = reshape([m%center(:, p), m%center(:, p) + d], [3, 2])
      pair%rotation = m%rotation(:, :, [p, q])
      pair%scale = m%scale([p, q])
      pair%shape = m%shape([p, q])
      pair%nmax = m%nmax([p, q])
      pair%sieve = m%sieve([p, q])
      target = 2.0e-3_wp * 0.25_wp
      ! bisection on the move t of p towards q: depth(lo) < target <= depth(hi)
      lo = 0.0_wp
      hi = dq
      do it = 1, 40
         t = 0.5_wp * (lo + hi)
         pair%center(:, 1) = m%center(:, p) + t * u
         call verify_model(pair, 48, rep, filter=.false.)
         if (rep%max_depth >= target) then
            hi = t
         else
            lo = t
         end if
      end do
      pair%center(:, 1) = m%center(:, p) + hi * u
      call verify_model(pair, 48, rep, filter=.false.)
      best = rep%max_depth
      m%center(:, p) = m%center(:, p) + hi * u
      call verify_model(m, 48, rep)
      print '(a,es10.3,a,es10.3,a,i0,a)', "        planted: move ", hi, " mm, depth ", best, " mm; found ", &
         rep%overlapping_pairs, " overlapping pair(s)"
      call check(error, rep%overlapping_pairs >= 1_i8 .and. any(rep%worst == p) .and. any(rep%worst == q), &
                 "planted overlap not found")
      if (allocated(error)) return
      call check(error, rep%max_depth, best, "planted depth", rel=1.0e-9_wp)
   end subroutine test_verify_planted


   !> A random expansion of degree 12 (mean radius 1, coefficients falling like 1/n^2) and, for a
   !> zonal harmonic Pbar_6^0, M2 = 36 sqrt(13/(4 pi)) exactly; along random great circles the
   !> largest second difference of r stays below M2.
   subroutine test_curvature_bound(error)
      type(error_type), allocatable, intent(out) :: error
      type(sh_expansion_type) :: shape
      type(rng_type) :: rng
      real(wp) :: a(0:12, 0:12), b(0:12, 0:12), e1(3), e2(3), h, s, worst, m2, r(-1:1)
      integer :: n, k, it
      a = 0.0_wp
      a(6, 0) = 1.0_wp
      b = 0.0_wp
      call new_sh_expansion_real(shape, a(0:6, 0:6), b(0:6, 0:6))
      call check(error, curvature_bound(shape), 36.0_wp * sqrt(13.0_wp / (16.0_wp * atan(1.0_wp))), &
                 "zonal M2", rel=1.0e-12_wp)
      if (allocated(error)) return
      call new_rng(rng, 21_i8, 0_i8)
      shape = random_shape(rng, 12)
      m2 = curvature_bound(shape)
      worst = 0.0_wp
      h = 1.0e-3_wp
      do it = 1, 200
         call random_frame(rng, e1, e2)
         do k = 0, 199
            s = 0.0314_wp * k
            do n = -1, 1
               r(n) = shape%radius_dir(cos(s + n * h) * e1 + sin(s + n * h) * e2)
            end do
            worst = max(worst, abs(r(1) - 2.0_wp * r(0) + r(-1)) / h**2)
         end do
      end do
      print '(a,es10.3,a,es10.3)', "        largest |d2r/ds2| found ", worst, ", bound ", m2
      call check(error, worst <= m2 .and. worst > 0.05_wp * m2, "M2 below a second derivative, or not meaningful")
   end subroutine test_curvature_bound

   !> Tables of an elongated ellipsoid (3:1:1, degree 14) and of a random degree-12 shape: r at
   !> 200,000 random directions (and at every cube-map node's neighbourhood) is below its cell's
   !> bound, and the bound is within 15 % of the mean radius above r; of 3,000 random balls near the
   !> surface, those found beyond have no point (200 random points each) inside the particle, and
   !> many are found beyond.
   subroutine test_radius_bounds(error)
      type(error_type), allocatable, intent(out) :: error
      type(sh_expansion_type) :: shape
      type(radius_bounds_type) :: bounds
      type(rng_type) :: rng
      real(wp) :: u(3), c(3), p(3), rad, excess, r0
      integer :: ishape, it, k, nbeyond
      logical :: inside
      call new_rng(rng, 22_i8, 0_i8)
      do ishape = 1, 2
         if (ishape == 1) then
            shape = ellipsoid_shape(3.0_wp, 1.0_wp, 1.0_wp, 14)
         else
            shape = random_shape(rng, 12)
         end if
         r0 = shape%mean_radius()
         call new_radius_bounds(bounds, shape, 6.0e-3_wp)
         excess = 0.0_wp
         do it = 1, 200000
            u = unit_vector(rng)
            call check(error, shape%radius_dir(u) <= bound_at(bounds, u), "r above its cell's bound")
            if (allocated(error)) return
            excess = max(excess, bound_at(bounds, u) - shape%radius_dir(u))
         end do
         print '(a,i0,a,i0,a,es10.3)', "        shape ", ishape, ": ", bounds%nc, &
            " cells per face edge, largest bound - r (of the mean radius) ", excess / r0
         call check(error, excess < 0.15_wp * r0, "bounds too loose to be of use")
         if (allocated(error)) return
         nbeyond = 0
         do it = 1, 3000
            u = unit_vector(rng)
            c = shape%radius_dir(u) * u * rng%uniform_range(0.97_wp, 1.3_wp)
            rad = r0 * 10.0_wp**rng%uniform_range(-3.0_wp, -0.5_wp)
            if (.not. ball_beyond(bounds, c, rad)) cycle
            nbeyond = nbeyond + 1
            inside = .false.
            do k = 1, 200
               p = c + rad * rng%uniform()**(1.0_wp / 3.0_wp) * unit_vector(rng)
               inside = inside .or. norm2(p) < shape%radius_dir(p)
            end do
            call check(error, .not. inside, "a point of a ball beyond the bounds is inside")
            if (allocated(error)) return
         end do
         print '(a,i0,a)', "        ", nbeyond, " of 3000 balls beyond"
         call check(error, nbeyond > 300, "too few balls found beyond")
         if (allocated(error)) return
      end do
   end subroutine test_radius_bounds

   !> Outside truth from the shapes' own radii: an ellipsoid (semi-axes 1.5, 1, 1, degree 14) and
   !> its copy side by side along y, their centres 2 r(y) + gap apart, and a sphere of radius 0.1
   !> at the ellipsoid's tip along x at distance r(x) + 0.1 + gap. Gaps of +1e-3 pass; -0.02 (the
   !> ellipsoids) and -0.01 (the sphere) fail with that radial depth along the line of centres
   !> (less by at most the sampling's curvature error, 2e-3).
   subroutine test_verify_ellipsoids(error)
      type(error_type), allocatable, intent(out) :: error
      type(model_type) :: m
      type(verify_report_type) :: rep
      real(wp) :: ry, rx
      integer :: k
      m = sphere_model(reshape([3.0_wp, 3.0_wp, 3.0_wp, 3.0_wp, 3.0_wp, 3.0_wp], [3, 2]), .true., &
                       [10.0_wp, 10.0_wp, 10.0_wp])
      m%shapes(1) = ellipsoid_shape(1.5_wp, 1.0_wp, 1.0_wp, 14)
      m%nmax = [14, 14]
      m%rotation(:, :, 1) = reshape([1.0_wp, 0.0_wp, 0.0_wp, 0.0_wp, 1.0_wp, 0.0_wp, 0.0_wp, 0.0_wp, 1.0_wp], [3, 3])
      m%rotation(:, :, 2) = m%rotation(:, :, 1)
      ry = m%shapes(1)%radius_dir([0.0_wp, 1.0_wp, 0.0_wp])
      rx = m%shapes(1)%radius_dir([1.0_wp, 0.0_wp, 0.0_wp])
      do k = 1, 2
         m%center(:, 2) = m%center(:, 1) + [0.0_wp, 2.0_wp * ry + merge(1.0e-3_wp, -0.02_wp, k == 1), 0.0_wp]
         call verify_model(m, 120, rep, filter=.false.)
         if (k == 1) then
            call check(error, rep%pairs_checked == 1_i8 .and. rep%overlapping_pairs == 0_i8, "ellipsoids at a gap flagged")
         else
            print '(a,es10.3,a)', "        ellipsoid overlap depth found ", rep%max_depth, " (exact 2.0e-2)"
            call check(error, rep%overlapping_pairs == 1_i8 .and. rep%max_depth <= 0.02_wp + 1.0e-9_wp .and. &
                       rep%max_depth > 0.018_wp, "ellipsoid overlap depth")
         end if
         if (allocated(error)) return
      end do
      ! a sphere of radius 0.1 (shape 2) at the tip along x
      m%shapes = [m%shapes(1), sphere_shape(0.1_wp)]
      m%shape_names = [character(len=len(m%shape_names)) :: "ellipsoid", "sphere"]
      m%shape(2) = 2
      m%nmax(2) = 0
      do k = 1, 2
         m%center(:, 2) = m%center(:, 1) + [rx + 0.1_wp + merge(1.0e-3_wp, -0.01_wp, k == 1), 0.0_wp, 0.0_wp]
         call verify_model(m, 120, rep, filter=.false.)
         if (k == 1) then
            call check(error, rep%pairs_checked == 1_i8 .and. rep%overlapping_pairs == 0_i8, "sphere at a gap flagged")
         else
            print '(a,es10.3,a)', "        sphere at the tip: depth found ", rep%max_depth, " (exact 1.0e-2)"
            call check(error, rep%overlapping_pairs == 1_i8 .and. rep%max_depth <= 0.01_wp + 1.0e-9_wp .and. &
                       rep%max_depth > 0.008_wp, "sphere overlap depth")
         end if
         if (allocated(error)) return
      end do
   end subroutine test_verify_ellipsoids

   !> A random expansion of degree nmax: mean radius 1, coefficients uniform in +-0.15/n^2.
   function random_shape(rng, nmax) result(shape)
      type(rng_type), intent(inout) :: rng
      integer, intent(in) :: nmax
      type(sh_expansion_type) :: shape
      real(wp) :: a(0:nmax, 0:nmax), b(0:nmax, 0:nmax)
      integer :: n, k
      a = 0.0_wp
      b = 0.0_wp
      a(0, 0) = sqrt(16.0_wp * atan(1.0_wp))
      do n = 1, nmax
         do k = 0, n
            a(n, k) = rng%uniform_range(-0.15_wp, 0.15_wp) / n**2
            if (k > 0) b(n, k) = rng%uniform_range(-0.15_wp, 0.15_wp) / n**2
         end do
      end do
      call new_sh_expansion_real(shape, a, b)
   end function random_shape

   !> A random unit vector (uniform on the sphere).
   function unit_vector(rng) result(u)
      type(rng_type), intent(inout) :: rng
      real(wp) :: u(3)
      u = [rng%normal(), rng%normal(), rng%normal()]
      u = u / norm2(u)
   end function unit_vector

   !> Two random orthonormal vectors (a random great circle).
   subroutine random_frame(rng, e1, e2)
      type(rng_type), intent(inout) :: rng
      real(wp), intent(out) :: e1(3), e2(3)
      e1 = unit_vector(rng)
      e2 = unit_vector(rng)
      e2 = e2 - dot_product(e1, e2) * e1
      e2 = e2 / norm2(e2)
   end subroutine random_frame

   subroutine keep_report(self, report)
      class(slab_only_type), intent(in) :: self
      type(verify_report_type), intent(inout) :: report
   end subroutine keep_report

   !> The audit of each slab (what rank r of n audits under MPI) summed over the slabs is the
   !> serial audit: pairs, cleared pairs, overlaps and walls, the largest penetration and its pair.
   !> 80 spheres at random in a 10 mm box, many overlapping (across slab borders and, periodic,
   !> across the box), and through the walls when not periodic.
   subroutine test_verify_slabs(error)
      type(error_type), allocatable, intent(out) :: error
      type(model_type) :: m
      type(verify_report_type) :: whole, part
      type(slab_only_type) :: split
      type(rng_type) :: rng
      real(wp) :: c(3, 80), depth
      integer(i8) :: pairs, cleared, over
      integer :: walls, n, r, ip, worst(2), ns(2)
      logical :: periodic
      call new_rng(rng, 11_i8, 0_i8)
      do ip = 1, 80
         c(:, ip) = [rng%uniform_range(0.0_wp, 10.0_wp), rng%uniform_range(0.0_wp, 10.0_wp), &
                     rng%uniform_range(0.0_wp, 10.0_wp)]
      end do
      ns = [2, 3]
      do ip = 0, 1
         periodic = ip == 1
         m = sphere_model(c, periodic, [10.0_wp, 10.0_wp, 10.0_wp])
         call verify_model(m, 12, whole, filter=.true.)
         call check(error, whole%overlapping_pairs > 20, "many overlaps expected")
         if (allocated(error)) return
         do n = 1, size(ns)
            pairs = 0
            cleared = 0
            over = 0
            walls = 0
            depth = 0.0_wp
            worst = 0
            split%nranks = ns(n)
            do r = 0, ns(n) - 1
               split%rank = r
               call verify_model(m, 12, part, filter=.true., split=split)
               pairs = pairs + part%pairs_checked
               cleared = cleared + part%pairs_cleared
               over = over + part%overlapping_pairs
               walls = walls + part%wall_violations
               depth = max(depth, part%max_depth)
               if (part%worst_depth == whole%worst_depth) worst = part%worst
            end do
            call check(error, pairs == whole%pairs_checked .and. cleared == whole%pairs_cleared .and. &
                       over == whole%overlapping_pairs .and. walls == whole%wall_violations, &
                       "the slabs' counts sum to the serial ones")
            if (allocated(error)) return
            call check(error, depth == whole%max_depth .and. all(worst == whole%worst), &
                       "the largest penetration and its pair are the serial ones")
            if (allocated(error)) return
         end do
         call check(error, periodic .or. whole%wall_violations > 0, "walls crossed expected")
         if (allocated(error)) return
      end do
   end subroutine test_verify_slabs
end module test_audit
