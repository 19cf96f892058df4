:- module(program_check,
          [ check_program_text/2        % +Id, +Text
          ]).
:- use_module(sandbox_policy, [safe_library/1]).
:- use_module(sandbox_check,
              [ check_body/3, with_scratch/3, code_refuse/2, plain_data/1,
                clause_parts/2, check_head/1 ]).
:- use_module(code_hooks, [qualified_hook/4, own_predicate/1]).
:- autoload(library(error), [must_be/2]).
:- autoload(library(lists), [member/2, append/2, append/3]).
:- autoload(library(apply), [maplist/2, maplist/3, include/3, exclude/3]).

:- multifile
    code_safety:mobile_hook/1,
    code_safety:moved_hook/2.

/** <module> Checking a program a peer sent

The program rules of code_safety.pl: a program loads into a module of
its own and may define its own predicates and the mobile hooks
(code_safety:mobile_hook/1); its directives may only declare them, load
libraries of an allow-list and name initialization goals. Every body and
initialization goal goes through the sandbox (sandbox_check.pl).
*/

%!  check_program_text(+Id, +Text) is det.
%
%   Check a program a peer sent (see the module comment) before it is
%   loaded as dfrl_program://Id into a module of its own (codeload.pl,
%   program_module/2): its clauses define its own predicates (none the
%   Prolog system, a library or the node calls by name: hook_refusal/3)
%   and the mobile hooks (mobile_hook/1); its directives declare them,
%   load safe libraries and name initialization goals, which are
%   checked here as bodies and run later under the agent bounds.
%
%   @error permission_error(install, code, Culprit)
%   @error syntax_error(...) if Text does not read.

check_program_text(Id, Text) :-
    must_be(atomic, Id),
    must_be(string, Text),
    setup_call_cleanup(open_string(Text, In),
                       read_program(In, Terms0),
                       close(In)),
    plain_data(Terms0),
    findall(Head, ( member(T, Terms0), raw_head(T, Head) ), Heads0),
    sort(Heads0, Heads),                        % each name is looked up once
    maplist(head_hook_check, Heads),
    maplist(expand, Terms0, Expanded),
    append(Expanded, Terms),
    partition_terms(Terms, Directives, Clauses),
    maplist(check_directive, Directives),
    maplist(program_clause, Clauses, Parts),
    findall(PI, ( member(own-H-_, Parts), functor(H, F, A), PI = F/A ), Own0),
    sort(Own0, Own),
    maplist(own_predicate, Own),
    findall(P, ( member(D, Directives), declared(D, P) ), Declared),
    include(own_part, Parts, OwnParts),
    findall(H-B, ( member(own-H-B, OwnParts), B \== true ), LocalRules),
    findall(F/A, ( member(own-H-_, OwnParts), functor(H, F, A) ), Local0),
    append(Declared, Local0, Local),
    findall(B, ( member(_-_-B, Parts), B \== true ), Bodies),
    findall(G, ( member(D, Directives), directive_init(D, G) ), Inits),
    append(Bodies, Inits, ToCheck),
    (   ToCheck == []
    ->  true
    ;   with_scratch(Local, LocalRules,
                     [S]>>forall(member(B, ToCheck), check_body(S, guid, B)))
    ).

%   Quasi quotations are parsed by hooks when the text is read (the
%   checker's read and the loader's): a program may not use them.
read_program(In, Terms) :-
    read_term(In, T, [module(user), syntax_errors(error), quasi_quotations(QQ)]),
    (   QQ \== []
    ->  code_refuse(quasi_quotation(T), 'quasi quotations run parsers when read')
    ;   T == end_of_file
    ->  Terms = []
    ;   Terms = [T|Rest],
        read_program(In, Rest)
    ).

%   A grammar rule's translation declares its head non_terminal/1 (in
%   the module it is read in): the declaration is the rule's, not a
%   directive of the program.
expand(T, Ts) :-
    expand_term(T, X),
    (   is_list(X) -> Ts0 = X ; Ts0 = [X] ),
    (   nonvar(T), T = (_ --> _)
    ->  exclude(non_terminal_decl, Ts0, Ts)
    ;   Ts = Ts0
    ).

non_terminal_decl((:- non_terminal(_))).

%   Clause heads are checked for hooks before the terms are expanded:
%   expansion runs the node's hooks on them (library(sandbox)'s refuses
%   a sandbox:safe_primitive/1 clause without naming the hook).
raw_head(T, M-(F/A)) :-
    nonvar(T),
    T \= (:- _),
    T \= (?- _),
    (   T = Q:(QH :- _),                        % Module:(Head :- Body)
        atom(Q), callable(QH)
    ->  strip_module(Q:QH, M, H),
        callable(H),
        functor(H, F, A)
    ;   T = (H0 --> _)
    ->  (   nonvar(H0), H0 = (H1, _) -> true ; H1 = H0 ),
        callable(H1),
        strip_module('$program':H1, M, H),
        callable(H),
        functor(H, F, A0),
        A is A0 + 2
    ;   clause_parts(T, QH-_),
        callable(QH),
        strip_module('$program':QH, M, H),
        callable(H),
        functor(H, F, A)
    ).

head_hook_check(M-(F/A)) :-
    (   M \== '$program',
        (   code_safety:mobile_hook(M:F/A)
        ;   code_safety:moved_hook(M:F/A, _)
        )
    ->  true                                    % program_clause/2 tells
    ;   M == '$program'
    ->  own_predicate(F/A)
    ;   qualified_hook(M, F/A, Q, Why)
    ->  code_refuse(hook(Q:F/A), Why)
    ;   true
    ).

partition_terms([], [], []).
partition_terms([(:- D)|Ts], [D|Ds], Cs) :- !, partition_terms(Ts, Ds, Cs).
partition_terms([(?- D)|Ts], [D|Ds], Cs) :- !, partition_terms(Ts, Ds, Cs).
partition_terms([C|Ts], Ds, [C|Cs]) :- partition_terms(Ts, Ds, Cs).

own_part(own-_-_).

%   program_clause(+Clause, -Where-Head-Body): Where is `own` for a
%   clause of the program's own module (an unqualified head), else the
%   module of a mobile hook.
program_clause(Clause, Where-H-B) :-
    clause_parts(Clause, QH-B),
    (   var(QH) -> code_refuse(clause_head(QH), 'a variable as clause head') ; true ),
    strip_module('$program':QH, M, H),
    check_head(H-B),
    functor(H, F, A),
    (   M == '$program'
    ->  Where = own
    ;   code_safety:mobile_hook(M:F/A)
    ->  Where = M
    ;   code_safety:moved_hook(M:F/A, To)
    ->  refuse_moved(M:F/A, To)
    ;   qualified_hook(M, F/A, Q, Why)
    ->  code_refuse(hook(Q:F/A), Why)
    ;   code_refuse(clause_head(M:H), 'a clause for another module')
    ).

%   Directives: declarations of the program's own predicates, libraries
%   and initialization goals (checked as bodies).
check_directive(D) :-
    (   var(D)
    ->  code_refuse(directive(D), 'a variable')
    ;   D = (A, B)
    ->  check_directive(A),
        check_directive(B)
    ;   declaration(D, Specs)
    ->  forall(pi_member(PI, Specs), check_declared(D, PI))
    ;   library_directive(D)
    ->  true
    ;   init_goal(D, _)
    ->  true
    ;   code_refuse(directive(D), 'not allowed in a program sent by a peer')
    ).

declaration(dynamic(S), S).
declaration(discontiguous(S), S).
declaration(multifile(S), S).
declaration(non_terminal(S), S).

pi_member(_, V) :- var(V), !, fail.
pi_member(PI, (A, B)) :- !, ( pi_member(PI, A) ; pi_member(PI, B) ).
pi_member(PI, [H|T]) :- !, ( pi_member(PI, H) ; pi_member(PI, T) ).
pi_member(_, []) :- !, fail.
pi_member(PI, PI).

check_declared(D, PI0) :-
    (   PI0 = M0:PI1 -> true ; M0 = '$program', PI1 = PI0 ),
    (   atom(M0), pred_indicator(PI1, F, A) -> M = M0
    ;   code_refuse(directive(D), 'not a predicate indicator')
    ),
    (   M == '$program'
    ->  (   D = multifile(_)
        ->  code_refuse(directive(D), 'declares a hook')
        ;   own_predicate(F/A)
        )
    ;   code_safety:mobile_hook(M:F/A)
    ->  true
    ;   code_safety:moved_hook(M:F/A, To)
    ->  refuse_moved(M:F/A, To)
    ;   qualified_hook(M, F/A, Q, Why)
    ->  code_refuse(hook(Q:F/A), Why)
    ;   code_refuse(directive(D), 'declares a predicate of another module')
    ).

refuse_moved(Old, New) :-
    code_refuse(moved_hook(Old, New), _).             % the culprit says it all

declared(D, F/A) :-
    declaration(D, Specs),
    pi_member(PI, Specs),
    pred_indicator(PI, F, A).

declared((A, B), PI) :-
    (   declared(A, PI) ; declared(B, PI) ).

%   Name/Arity, or Name//Arity of a non-terminal (Arity + 2 arguments).
pred_indicator(PI, F, A) :-
    nonvar(PI),
    (   PI = F/A
    ->  atom(F), integer(A)
    ;   PI = F//A0
    ->  atom(F), integer(A0),
        A is A0 + 2
    ).

library_directive(use_module(library(X))) :- safe_library(X).
library_directive(use_module(library(X), _)) :- safe_library(X).
library_directive(ensure_loaded(library(X))) :- safe_library(X).

%   initialization(G, main) would halt the node after G, the other
%   moments (restore, program, after_load) run G when the program
%   cannot be checked again: only now and after loading are allowed.
%   Both run after the program is loaded, under the agent bounds
%   (codeload.pl).
init_goal(initialization(G), G).
init_goal(initialization(G, now), G).

directive_init(D, G) :-
    (   init_goal(D, G)
    ;   D = (A, B),
        (   directive_init(A, G) ; directive_init(B, G) )
    ).
